"""`kinema batch`: many motions from a JSONL jobs file, resumable, on local processes or a Ray cluster.

- kinema.batch.spec: the jobs file (one JSON object per line) and its resolution into worker payloads;
- kinema.batch.worker: the model loaded once per worker; a job in, file bytes and the report out;
- kinema.batch.executors: in-process, local process pool, Ray actors (``--ray local|auto|ADDRESS``);
- kinema.batch.manifest: ``manifest.jsonl``, torn-line repair, stale temp files, the folder lock;
- kinema.batch.runner: `run_batch` (resume, atomic writes, progress, per-line failures);
- kinema.batch.bench: motions per minute against the number of workers.

docs/server.md documents the jobs format, the manifest and the throughput.
"""
