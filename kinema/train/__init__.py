"""Training of the denoiser (Kimodo Sec. 4.3): the Eq. 1 loss, phase-2 constraint sampling and friends."""
