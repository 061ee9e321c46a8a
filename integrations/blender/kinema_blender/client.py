"""The HTTP half of the Blender add-on: ask a kinema server for a motion and get BVH text back.

Why a module without ``bpy``: it runs (and is tested) outside Blender too, with nothing but the standard
library (Blender's Python has no third-party HTTP client). Errors from the server come back as
`KinemaClientError` with the server's own message, e.g. ``$.seconds: Input should be less than or
equal to 30``, so the add-on can show it to the user as it is.
"""

from __future__ import annotations

import json
import urllib.error
import urllib.request


class KinemaClientError(Exception):
    """The server refused the request or could not be reached; the message says why."""


def _detail(body: bytes) -> str:
    """The server's error text: validation items as ``path: msg`` joined, else ``detail``."""
    try:
        detail = json.loads(body.decode("utf-8")).get("detail")
    except (ValueError, AttributeError, UnicodeDecodeError):
        return body[:200].decode("utf-8", "replace")
    if isinstance(detail, list):
        return "; ".join(f"{d.get('path', '$')}: {d.get('msg', '')}" for d in detail if isinstance(d, dict))
    return str(detail)


def request_json(url: str, api_key: str = "", body: dict | None = None, timeout: float = 300.0) -> dict:
    """GET (``body`` None) or POST JSON to ``url`` and return the JSON answer; raises KinemaClientError."""
    data = None if body is None else json.dumps(body).encode("utf-8")
    req = urllib.request.Request(url, data=data, method="GET" if body is None else "POST")
    req.add_header("Accept", "application/json")
    if data is not None:
        req.add_header("Content-Type", "application/json")
    if api_key:
        req.add_header("Authorization", f"Bearer {api_key}")
    try:
        with urllib.request.urlopen(req, timeout=timeout) as resp:  # noqa: S310 (the user's own server URL)
            return json.loads(resp.read().decode("utf-8"))
    except urllib.error.HTTPError as err:
        raise KinemaClientError(f"HTTP {err.code}: {_detail(err.read())}") from None
    except (urllib.error.URLError, TimeoutError, OSError) as err:
        raise KinemaClientError(f"cannot reach the kinema server at {url}: {err}") from None


def generate_bvh(server: str, *, prompt: str, seconds: float, steps: int = 0, seed: int = 0, api_key: str = "",
                 model: str = "", rig: str = "", timeout: float = 300.0) -> tuple[str, dict]:
    """``(BVH text, report)`` of one motion from ``POST {server}/v1/generate``; ``steps`` 0 = the model's,
    ``model`` "" = the server's first, ``rig`` "" = the model's own skeleton (a model for any rig needs a
    rig id from ``GET /v1/models``)."""
    body: dict = {"prompt": prompt, "seconds": seconds, "seed": seed, "format": "bvh"}
    if steps > 0:
        body["steps"] = steps
    if model:
        body["model"] = model
    if rig:
        body["rig"] = rig
    answer = request_json(server.rstrip("/") + "/v1/generate", api_key, body, timeout)
    motions = answer.get("motions") or []
    if not motions or motions[0].get("encoding") != "text":
        raise KinemaClientError("the server answered without a BVH motion")
    return motions[0]["data"], answer.get("report", {})
