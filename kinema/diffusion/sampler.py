"""DDIM sampler driven by an x0-predicting denoiser (Kimodo Sec. 4.4: DDIM, 100 steps by default).

The API follows the style of a diffusers scheduler: ``set_timesteps`` chooses the inference steps,
``step`` moves one step back in time, ``add_noise`` is the forward process, and ``config`` /
``save_json`` / ``load_json`` store the settings next to the model weights so a checkpoint always
samples with the schedule it was trained on.

With ``eta = 0`` (the default, as in the paper) sampling is deterministic given the initial noise;
``eta = 1`` recovers DDPM-like ancestral sampling on the sub-sequence of steps.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch

from kinema.diffusion.schedule import NoiseSchedule
from kinema.errors import KinemaError

TIMESTEP_SPACINGS = ("trailing", "leading")

#: ``denoise_fn(x_t, t_batch) -> x0_pred``; ``t_batch`` is a LongTensor (B,) of 0-based steps.
DenoiseFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def kept_steps(num_steps: int, strength: float) -> int:
    """How many of ``num_steps`` DDIM steps a start at ``strength`` (0, 1] runs: at least one."""
    return max(1, round(strength * num_steps))


def spaced_timesteps(num_train_steps: int, num_inference_steps: int, spacing: str = "trailing") -> list[int]:
    """``num_inference_steps`` evenly spaced, strictly descending 0-based steps out of ``num_train_steps``.

    "trailing" (default) counts back from the end: ``round(T - i T / n) - 1`` for ``i = 0..n-1``, so the
    first step is always ``T - 1`` -- sampling starts from pure noise, matching how the model was
    trained, and the last step lands near ``T / n - 1``.  "leading" is ``i * (T // n)`` reversed, which
    starts below ``T - 1`` whenever ``n`` does not divide ``T`` evenly, leaving residual signal that the
    initial N(0, I) draw does not have (Lin et al., "Common Diffusion Noise Schedules and Sample Steps
    are Flawed", 2024).  Integer arithmetic (round-half-up) keeps the result exact for any ``n <= T``.
    """
    T, n = num_train_steps, num_inference_steps
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= T:
        raise ValueError(f"num_inference_steps must be an int in [1, {T}], got {n!r}")
    if spacing == "trailing":
        return [(2 * (n - i) * T + n) // (2 * n) - 1 for i in range(n)]
    if spacing == "leading":
        return [i * (T // n) for i in reversed(range(n))]
    raise ValueError(f"unknown timestep spacing {spacing!r}; expected one of {TIMESTEP_SPACINGS}")


class DDIMSampler:
    """Deterministic (eta = 0) or stochastic DDIM sampling from an x0 prediction.

    Args:
        schedule: the training noise schedule (default: cosine, T = 1000).
        num_inference_steps: denoising steps used by ``sample`` (paper default 100).
        eta: DDIM stochasticity; 0 = deterministic (paper), 1 = DDPM-like.
        timestep_spacing: "trailing" (default, first step is T - 1) or "leading".
    """

    def __init__(
        self,
        schedule: NoiseSchedule | None = None,
        num_inference_steps: int = 100,
        eta: float = 0.0,
        timestep_spacing: str = "trailing",
    ) -> None:
        self.schedule = schedule if schedule is not None else NoiseSchedule()
        if not isinstance(eta, (int, float)) or isinstance(eta, bool) or not math.isfinite(eta) or eta < 0:
            raise ValueError(f"eta must be a finite float >= 0, got {eta!r}")
        if timestep_spacing not in TIMESTEP_SPACINGS:
            raise ValueError(f"unknown timestep spacing {timestep_spacing!r}; expected {TIMESTEP_SPACINGS}")
        self.eta = float(eta)
        self.timestep_spacing = timestep_spacing
        self._abar = self.schedule.alphas_cumprod  # float64 copy, used for the DDIM coefficients
        self.num_inference_steps = 0
        self.timesteps = torch.empty(0, dtype=torch.long)
        self._prev: dict[int, int] = {}
        self.set_timesteps(num_inference_steps)

    # ------------------------------------------------------------------ timesteps
    @property
    def num_train_steps(self) -> int:
        """T of the underlying training schedule."""
        return self.schedule.num_train_steps

    def set_timesteps(self, num_inference_steps: int) -> None:
        """Choose ``num_inference_steps`` descending steps; fills ``self.timesteps`` (LongTensor (n,))."""
        steps = spaced_timesteps(self.num_train_steps, num_inference_steps, self.timestep_spacing)
        self.num_inference_steps = num_inference_steps
        self.timesteps = torch.tensor(steps, dtype=torch.long)
        # Each step's predecessor in the reverse process; -1 means "clean data" (alpha-bar = 1).
        self._prev = {t: (steps[i + 1] if i + 1 < len(steps) else -1) for i, t in enumerate(steps)}

    def previous_timestep(self, t: int) -> int:
        """The step after ``t`` in ``self.timesteps`` (-1 after the last one)."""
        try:
            return self._prev[t]
        except KeyError:
            raise ValueError(f"timestep {t} is not one of the current inference timesteps") from None

    # ------------------------------------------------------------------ update
    def step(
        self,
        x0_pred: torch.Tensor,
        t: int | torch.Tensor,
        x_t: torch.Tensor,
        generator: torch.Generator | None = None,
    ) -> torch.Tensor:
        """One DDIM update from ``x_t`` at step ``t`` to the previous step of ``self.timesteps``.

        The model predicts x0, so the noise is recovered as
        ``eps = (x_t - sqrt(abar_t) x0) / sqrt(1 - abar_t)`` and
        ``x_prev = sqrt(abar_prev) x0 + sqrt(1 - abar_prev - sigma^2) eps + sigma z`` with
        ``sigma = eta sqrt((1 - abar_prev) / (1 - abar_t)) sqrt(1 - abar_t / abar_prev)``.
        At the final step (previous step "-1", abar = 1) this is exactly ``x0_pred``, returned as is.
        ``t`` is a Python int or a tensor whose entries all hold the same step.
        """
        t = self._as_step(t)
        return self.step_to(x0_pred, t, self.previous_timestep(t), x_t, generator)

    def step_to(
        self, x0_pred: torch.Tensor, t: int, prev: int, x_t: torch.Tensor, generator: torch.Generator | None = None,
    ) -> torch.Tensor:
        """The DDIM update of :meth:`step` from step ``t`` to an explicit earlier step ``prev`` (-1 = clean).

        Pure: reads no per-call state, so one sampler can serve several threads with different step counts.
        """
        if x0_pred.shape != x_t.shape:
            raise ValueError(f"x0_pred shape {tuple(x0_pred.shape)} != x_t shape {tuple(x_t.shape)}")
        if prev < 0:
            return x0_pred
        abar_t = float(self._abar[t])
        abar_prev = float(self._abar[prev])
        eps = (x_t - math.sqrt(abar_t) * x0_pred) / math.sqrt(1.0 - abar_t)
        sigma = 0.0
        if self.eta > 0:
            sigma = self.eta * math.sqrt((1.0 - abar_prev) / (1.0 - abar_t) * (1.0 - abar_t / abar_prev))
        dir_coef = math.sqrt(max(1.0 - abar_prev - sigma**2, 0.0))
        x_prev = math.sqrt(abar_prev) * x0_pred + dir_coef * eps
        if sigma > 0:
            x_prev = x_prev + sigma * _randn_like(x_t, generator)
        return x_prev

    def add_noise(self, x0: torch.Tensor, noise: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """Forward process (diffusers argument order); same as ``schedule.q_sample(x0, t, noise)``."""
        return self.schedule.q_sample(x0, t, noise)

    # ------------------------------------------------------------------ full loop
    @torch.no_grad()
    def sample(
        self,
        denoise_fn: DenoiseFn,
        shape: Sequence[int],
        generator: torch.Generator | None = None,
        progress: bool = False,
        device: torch.device | str | None = None,
        dtype: torch.dtype = torch.float32,
        init_noise: torch.Tensor | None = None,
        num_inference_steps: int | None = None,
        on_step: Callable[[int, int], None] | None = None,
        start_x0: torch.Tensor | None = None,
        strength: float = 1.0,
    ) -> torch.Tensor:
        """Run the whole reverse process and return the final x0 (shape ``shape``).

        With ``start_x0`` (shape ``shape``, normalised), only the last ``strength`` share of the steps
        runs (at least one), starting from ``start_x0`` noised to the first of them (SDEdit): the result
        keeps the start's large-scale shape and redraws its details.

        ``num_inference_steps`` (default: the sampler's own setting) applies to this call only: the
        sampler is not changed, so calls from several threads with different step counts do not interfere.

        Starts from N(0, I) noise drawn from ``generator`` (on the generator's device, then moved to
        ``device``, so a seed gives the same result whatever device the model runs on) unless
        ``init_noise`` is given, then calls ``denoise_fn(x_t, t_batch)`` once per inference step.
        The same ``generator`` also feeds the per-step noise when ``eta > 0``.
        ``progress=True`` shows a tqdm bar; ``on_step(done, total)`` is called after each step.
        """
        if init_noise is not None:
            if tuple(init_noise.shape) != tuple(shape):
                raise ValueError(f"init_noise shape {tuple(init_noise.shape)} != {tuple(shape)}")
            x = init_noise.to(device=device, dtype=dtype)
        else:
            gen_device = generator.device if generator is not None else "cpu"
            x = torch.randn(tuple(shape), generator=generator, device=gen_device, dtype=dtype)
            x = x.to(device=device) if device is not None else x
        if num_inference_steps is None:
            steps = self.timesteps.tolist()
        else:
            steps = spaced_timesteps(self.num_train_steps, num_inference_steps, self.timestep_spacing)
        if start_x0 is not None:
            steps = steps[len(steps) - kept_steps(len(steps), strength) :]
            t0 = torch.full((x.shape[0],), steps[0], dtype=torch.long, device=x.device)
            x = self.add_noise(start_x0.to(device=x.device, dtype=x.dtype), x, t0)
        pairs = list(zip(steps, steps[1:] + [-1], strict=True))
        if progress:
            from tqdm.auto import tqdm

            pairs = tqdm(pairs, desc="DDIM", leave=False)
        batch = x.shape[0]
        for i, (t, prev) in enumerate(pairs):
            t_batch = torch.full((batch,), t, dtype=torch.long, device=x.device)
            x0_pred = denoise_fn(x, t_batch)
            x = self.step_to(x0_pred, t, prev, x, generator=generator)
            if on_step is not None:
                on_step(i + 1, len(pairs))
        return x

    # ------------------------------------------------------------------ config
    @property
    def config(self) -> dict[str, Any]:
        """The settings that define this sampler, JSON-serialisable (see ``to_dict``)."""
        return self.to_dict()

    def to_dict(self) -> dict[str, Any]:
        """Settings as a plain dict; ``from_dict(to_dict())`` rebuilds an identical sampler."""
        return {
            "_class_name": type(self).__name__,
            "schedule": self.schedule.to_dict(),
            "num_inference_steps": self.num_inference_steps,
            "eta": self.eta,
            "timestep_spacing": self.timestep_spacing,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DDIMSampler:
        """Rebuild from ``to_dict`` output; malformed configs raise ``KinemaError``."""
        if not isinstance(data, dict):
            raise KinemaError(f"sampler config must be a mapping, got {type(data).__name__}")
        data = dict(data)
        name = data.pop("_class_name", cls.__name__)
        if name != cls.__name__:
            raise KinemaError(f"sampler config is for {name!r}, not {cls.__name__!r}")
        unknown = set(data) - {"schedule", "num_inference_steps", "eta", "timestep_spacing"}
        if unknown:
            raise KinemaError(f"unknown sampler config keys: {sorted(unknown)}")
        schedule = NoiseSchedule.from_dict(data.pop("schedule", {}))
        try:
            return cls(schedule=schedule, **data)
        except (TypeError, ValueError) as exc:
            raise KinemaError(f"bad sampler config: {exc}") from exc

    def save_json(self, path: str | Path) -> None:
        """Write ``to_dict()`` as JSON to the file ``path`` (parent folders are created)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), indent=2) + "\n", encoding="utf-8")

    @classmethod
    def load_json(cls, path: str | Path) -> DDIMSampler:
        """Read a sampler saved by ``save_json``; a missing or invalid file raises ``KinemaError``."""
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise KinemaError(f"{path}: cannot read sampler config: {exc.strerror or exc}") from exc
        except json.JSONDecodeError as exc:
            raise KinemaError(f"{path}: invalid JSON at line {exc.lineno}: {exc.msg}") from exc
        try:
            return cls.from_dict(data)
        except KinemaError as exc:
            raise KinemaError(f"{path}: {exc}") from exc

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(schedule={self.schedule!r}, "
            f"num_inference_steps={self.num_inference_steps}, eta={self.eta}, "
            f"timestep_spacing={self.timestep_spacing!r})"
        )

    # ------------------------------------------------------------------ helpers
    def _as_step(self, t: int | torch.Tensor) -> int:
        """Reduce ``t`` (int, 0-d tensor, or a (B,) tensor of one repeated value) to a Python int."""
        if isinstance(t, torch.Tensor):
            if t.numel() == 0:
                raise ValueError("t is an empty tensor")
            flat = t.reshape(-1)
            if flat.numel() > 1 and not bool((flat == flat[0]).all()):
                raise ValueError("DDIMSampler.step needs one timestep for the whole batch")
            return int(flat[0])
        return int(t)


def _randn_like(x: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
    """Standard normal noise shaped like ``x``, drawn on the generator's device for reproducibility."""
    gen_device = generator.device if generator is not None else x.device
    z = torch.randn(x.shape, generator=generator, device=gen_device, dtype=x.dtype)
    return z.to(x.device)
