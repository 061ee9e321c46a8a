"""Diffusion machinery: noise schedule, DDIM sampler and (separated) classifier-free guidance.

See Kimodo Sec. 4.3-4.4: DDPM training with T = 1000 and x0 prediction, DDIM sampling (eta 0,
100 steps by default) and guidance split into text and constraint terms.
"""

from kinema.diffusion.guidance import (
    Guidance,
    GuidanceMode,
    branches,
    combine,
    split_branches,
    stack_branches,
)
from kinema.diffusion.sampler import DDIMSampler, spaced_timesteps
from kinema.diffusion.schedule import NoiseSchedule

__all__ = [
    "DDIMSampler",
    "Guidance",
    "GuidanceMode",
    "NoiseSchedule",
    "branches",
    "combine",
    "spaced_timesteps",
    "split_branches",
    "stack_branches",
]
