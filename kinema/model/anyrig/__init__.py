"""The per-joint any-rig denoiser (denoiser), its config (config) and its checkpoint loader (loading)."""
