"""kinema: text- and constraint-driven skeletal motion generation for any rig."""
