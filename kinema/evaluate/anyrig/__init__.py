"""Evaluation of an any-rig model per rig (suite) and per action group (groups)."""
