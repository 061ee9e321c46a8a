"""The FastAPI application: routes, error answers and guards, built by `create_app` from a config.

Endpoints (docs/server.md has examples): ``POST /v1/generate`` (answer when done), ``POST /v1/jobs``
+ ``GET /v1/jobs/{id}`` (+ ``/result`` and ``/motions/{i}`` downloads) for long work, ``GET /v1/models``,
``GET /healthz``; OpenAPI at ``/openapi.json`` and a docs page at ``/docs``. Why no
``from __future__ import annotations`` here: the request class is built per config inside
`create_app`, and FastAPI must see it as a real annotation.
"""

import asyncio
import logging
import time
from contextlib import asynccontextmanager
from typing import Annotated

from fastapi import APIRouter, Depends, FastAPI, HTTPException
from fastapi import Path as PathParam
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse, Response

from kinema import __version__
from kinema.server.config import ServerConfig, ServerLimits
from kinema.server.encode import MEDIA, SUFFIX, compact, expand
from kinema.server.errors import RequestError, from_pydantic, json_syntax_error
from kinema.server.jobs import Job, JobStore, StoreFull
from kinema.server.middleware import BodyLimitMiddleware, api_key_dependency
from kinema.server.models import ModelRegistry
from kinema.server.pool import PoolFull, WorkerPool
from kinema.server.run import Prepared, execute, prepare
from kinema.server.schemas import (
    ErrorOut,
    GenerateResponse,
    HealthOut,
    JobOut,
    ModelsOut,
    ValidationErrorOut,
    build_request_model,
)
from kinema.server.stream import add_stream_route

log = logging.getLogger("kinema.server")
JobId = Annotated[str, PathParam(pattern="^[0-9a-f]{32}$", description="the id POST /v1/jobs returned")]
RETRY_AFTER = {"Retry-After": {"description": "seconds to wait before retrying", "schema": {"type": "integer"}}}
ERRORS = {
    400: {"model": ErrorOut, "description": "the body is not JSON text (a syntax error, or not UTF-8)"},
    413: {"model": ErrorOut, "description": "request body too large"},
    422: {"model": ValidationErrorOut, "description": "invalid request; each item names the field"},
    429: {"model": ErrorOut, "description": "queue full", "headers": RETRY_AFTER},
}
TIMEOUT = {504: {"model": ErrorOut, "description": "took longer than the per-request timeout (use jobs)"}}
JOB_ERRORS = {404: {"model": ErrorOut, "description": "no such job (or it expired), or no such motion"},
              409: {"model": ErrorOut, "description": "the job has not finished, or failed inside the server"},
              422: {"model": ValidationErrorOut, "description": "a malformed id, or the job's request was invalid"}}
FILE_TYPES = {200: {"description": "the motion file", "content": {
    "text/plain": {"schema": {"type": "string"}}, "application/octet-stream": {"schema": {"type": "string"}},
    "application/json": {"schema": {"type": "object"}}}}}
BUSY = "all workers are busy and the queue is full"


def busy(retry_after: int, what: str) -> JSONResponse:
    """The 429 answer: the queue (or job store) is full; ``Retry-After`` says when to try again."""
    return JSONResponse({"detail": f"{what}; retry in {retry_after} s"}, status_code=429,
                        headers={"Retry-After": str(retry_after)})


def create_app(config: ServerConfig, registry: ModelRegistry) -> FastAPI:
    """The application for one configuration and set of loaded models."""
    limits = config.limits
    pool = WorkerPool(limits.workers, limits.queue)
    store = JobStore(limits.max_jobs, limits.job_ttl_s)

    @asynccontextmanager
    async def lifespan(_app):
        yield
        pool.shutdown()

    app = FastAPI(title="kinema", version=__version__, lifespan=lifespan,
                  description="Text- and constraint-driven skeletal motion generation (docs/server.md).")
    _install_error_handlers(app)
    app.add_middleware(BodyLimitMiddleware, max_bytes=limits.max_body_bytes, read_timeout_s=limits.read_timeout_s)
    if config.cors_origins:
        app.add_middleware(CORSMiddleware, allow_origins=list(config.cors_origins), allow_methods=["GET", "POST"],
                           allow_headers=["Authorization", "X-API-Key", "Content-Type"])
    guards = [Depends(api_key_dependency(config.api_keys))] if config.api_keys else []
    auth_errors = {401: {"model": ErrorOut, "description": "missing or wrong API key"}} if config.api_keys else {}
    v1 = APIRouter(prefix="/v1", dependencies=guards, responses=auth_errors)
    request_model = build_request_model(limits)
    _add_generate_route(v1, request_model, registry, pool, limits)
    _add_job_routes(v1, request_model, registry, pool, store, limits)
    _add_info_route(v1, registry, limits)
    app.include_router(v1)
    add_stream_route(app, registry, config)

    @app.get("/healthz", response_model=HealthOut, tags=["info"])
    async def healthz() -> dict:
        """Liveness: the models are loaded and the pool answers (no API key needed)."""
        return {"status": "ok", "models": registry.names, "pending": pool.pending, "capacity": pool.capacity,
                "jobs": len(store)}

    return app


def _install_error_handlers(app: FastAPI) -> None:
    @app.exception_handler(RequestValidationError)
    async def _invalid(_request, exc: RequestValidationError):
        syntax = json_syntax_error(exc.errors())
        if syntax is not None:
            return JSONResponse({"detail": syntax}, status_code=400)
        return JSONResponse({"detail": from_pydantic(exc.errors())}, status_code=422)

    @app.exception_handler(RequestError)
    async def _bad_request(_request, exc: RequestError):
        return JSONResponse({"detail": exc.items}, status_code=422)


def _add_generate_route(v1: APIRouter, request_model, registry: ModelRegistry, pool: WorkerPool,
                        limits: ServerLimits) -> None:
    @v1.post("/generate", response_model=GenerateResponse, tags=["generate"], responses=ERRORS | TIMEOUT)
    async def generate(body: request_model):
        """Generate motion(s); answers with them and the residual report when done."""
        prep = await asyncio.to_thread(prepare, body, registry, limits.max_steps)  # reads inline rigs
        try:
            future = pool.submit(execute, prep)
        except PoolFull as full:
            return busy(full.retry_after, BUSY)
        try:
            return await asyncio.wait_for(asyncio.wrap_future(future), limits.timeout_s)
        except TimeoutError:
            return JSONResponse({"detail": f"generation took longer than {limits.timeout_s:g} s (the request "
                                           "timeout); use POST /v1/jobs for long work"}, status_code=504)


def _add_job_routes(v1: APIRouter, request_model, registry: ModelRegistry, pool: WorkerPool, store: JobStore,
                    limits: ServerLimits) -> None:
    @v1.post("/jobs", response_model=JobOut, status_code=202, tags=["jobs"], responses=ERRORS)
    async def create_job(body: request_model):
        """Queue a generation; poll ``GET /v1/jobs/{id}``, then download ``/result`` or ``/motions/{i}``."""
        prep = await asyncio.to_thread(prepare, body, registry, limits.max_steps)  # reads inline rigs
        try:
            job = store.create()
        except StoreFull as full:
            return busy(pool.retry_after(), str(full))
        try:
            pool.submit(_run_job, store, job, prep)
        except PoolFull as full:
            store.discard(job.id)
            return busy(full.retry_after, BUSY)
        return JSONResponse(_job_out(store, job), status_code=202, headers={"Location": f"/v1/jobs/{job.id}"})

    @v1.get("/jobs/{job_id}", response_model=JobOut, tags=["jobs"], responses=JOB_ERRORS)
    async def get_job(job_id: JobId) -> dict:
        """A job's state, and its download links once done."""
        return _job_out(store, _find(store, job_id))

    @v1.get("/jobs/{job_id}/result", response_model=GenerateResponse, tags=["jobs"], responses=JOB_ERRORS)
    async def job_result(job_id: JobId):
        """The finished job's answer, as ``POST /v1/generate`` gives it."""
        job = _find(store, job_id)
        return _unfinished(job) or expand(job.result)

    @v1.get("/jobs/{job_id}/motions/{index}", tags=["jobs"], response_class=Response,
            responses=JOB_ERRORS | FILE_TYPES)
    async def job_motion(job_id: JobId, index: Annotated[int, PathParam(ge=0, le=10_000)]):
        """One motion of a finished job as a file (BVH text, npz or JSON)."""
        job = _find(store, job_id)
        early = _unfinished(job)
        if early is not None:
            return early
        motions = job.result["motions"]
        if index >= len(motions):
            return JSONResponse({"detail": f"the job has {len(motions)} motion(s)"}, status_code=404)
        m = motions[index]
        return Response(m["payload"], media_type=MEDIA[m["encoding"]],
                        headers={"Content-Disposition": f'attachment; filename="{m["filename"]}"'})


def _add_info_route(v1: APIRouter, registry: ModelRegistry, limits: ServerLimits) -> None:
    @v1.get("/models", response_model=ModelsOut, tags=["info"])
    async def models() -> dict:
        """The served models, their rigs, and the limits each request must keep to."""
        return {"models": [m.info(limits.as_dict()) for m in registry.models.values()], "formats": sorted(SUFFIX),
                "limits": limits.as_dict()}


def _run_job(store: JobStore, job: Job, prep: Prepared) -> None:
    """Worker side of a job: run it and record the result or the error (never raises)."""
    store.update(job, status="running", started=time.time())
    try:
        result = execute(prep)
    except RequestError as err:
        store.update(job, status="failed", error=err.items, finished=time.time())
    except Exception as err:  # a bug: keep the server up, tell the client, log the traceback
        log.exception("job %s failed", job.id)
        store.update(job, status="failed", error=f"internal error ({type(err).__name__})", finished=time.time())
    else:
        store.update(job, status="done", result=compact(result), finished=time.time())


def _find(store: JobStore, job_id: str) -> Job:
    job = store.get(job_id)
    if job is None:
        raise HTTPException(404, "no such job (unknown id, or its result expired)")
    return job


def _unfinished(job: Job) -> JSONResponse | None:
    """The answer for a job without a result (409 running / internal failure, 422 invalid request), or None."""
    if job.status == "done":
        return None
    if job.status == "failed" and isinstance(job.error, list):
        return JSONResponse({"detail": job.error}, status_code=422)
    if job.status == "failed":
        return JSONResponse({"detail": f"the job failed: {job.error}"}, status_code=409)
    return JSONResponse({"detail": f"the job is {job.status}; poll GET /v1/jobs/{job.id}"}, status_code=409)


def _job_out(store: JobStore, job: Job) -> dict:
    links = {}
    if job.status == "done":
        links = {"result": f"/v1/jobs/{job.id}/result",
                 "motions": [f"/v1/jobs/{job.id}/motions/{i}" for i in range(len(job.result["motions"]))]}
    return {"id": job.id, "status": job.status, "created": job.created, "started": job.started,
            "finished": job.finished, "expires": store.expires(job), "error": job.error} | links
