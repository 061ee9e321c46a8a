"""kinema's HTTP API (``kinema serve``): FastAPI + uvicorn around a loaded model, for tools and game engines.

- kinema.server.config: `ServerConfig` / `ServerLimits` (every limit, the bind and API-key rules);
- kinema.server.schemas: request/response models (unknown keys rejected, limits in the OpenAPI schema);
- kinema.server.app: `create_app` (routes, error answers, body limit, API key, CORS);
- kinema.server.pool / jobs: the bounded worker pool and the bounded, expiring job store;
- kinema.server.run / encode: one request through ``KinemaModel.generate`` to BVH / npz / JSON.

docs/server.md documents the endpoints, limits and security rules. Needs the ``server`` extra
(``pip install 'kinema[server]'``).
"""
