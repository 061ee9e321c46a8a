"""The motion denoiser network (Kimodo Sec. 4.2): configs, presets and the two-stage transformer."""

from kinema.model.config import PRESETS, ModelConfig, get_config, preset_names
from kinema.model.denoiser import Denoiser, impute, local_root_stats, padded_local_root

__all__ = [
    "PRESETS",
    "Denoiser",
    "ModelConfig",
    "get_config",
    "impute",
    "local_root_stats",
    "padded_local_root",
    "preset_names",
]
