"""A spy on a loaded human model's denoiser: the batch size (rows) of every forward pass, for tests that
count guidance branches and samples per step (test_generate_speed, test_guidance_cache)."""

from __future__ import annotations


def record_forward_rows(model, monkeypatch) -> list[int]:
    """A list that receives the row count of every ``model.loaded.denoiser.forward`` call from now on
    (undone by ``monkeypatch`` at the end of the test)."""
    rows: list[int] = []
    den = model.loaded.denoiser
    forward = den.forward

    def spy(x_t, *args, **kwargs):
        rows.append(x_t.shape[0])
        return forward(x_t, *args, **kwargs)

    monkeypatch.setattr(den, "forward", spy)
    return rows
