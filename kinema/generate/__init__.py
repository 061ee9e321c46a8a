"""Generation: sampling features from a trained denoiser and turning them into motions."""
