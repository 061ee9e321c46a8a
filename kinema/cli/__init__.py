"""The `kinema` command line. Each sub-command lives in its own module and registers itself here.

Errors caused by user input (`KinemaError`) are printed as one line on stderr with exit status 2;
anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from kinema.errors import KinemaError


def build_parser() -> argparse.ArgumentParser:
    """Assemble the parser from the sub-command modules (imported lazily to keep start-up fast)."""
    from kinema.cli import (
        app,
        batch,
        bench,
        convert,
        data,
        evaluate,
        evaluate_anyrig,
        evaluate_retrieval,
        export,
        export_onnx,
        generate,
        inspect,
        render,
        retarget,
        robot,
        serve,
        stream,
        train,
        train_anyrig,
        train_anyrig_root,
        web,
    )

    parser = argparse.ArgumentParser(prog="kinema", description="Text + constraint driven motion generation.")
    sub = parser.add_subparsers(dest="command", required=True)
    faces = (serve, batch, app)
    for module in (
        generate,
        convert,
        inspect,
        data,
        train,
        train_anyrig,
        train_anyrig_root,
        export,
        export_onnx,
        bench,
        render,
        retarget,
        robot,
        stream,
        evaluate,
        evaluate_anyrig,
        evaluate_retrieval,
        web,
        *faces,
    ):
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script; returns the process exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    before = os.environ.get("KINEMA_PRECISION")
    if getattr(args, "precision", None):  # every model this command (its server, workers) loads
        os.environ["KINEMA_PRECISION"] = args.precision
    try:
        result = args.func(args)
    except KinemaError as err:
        print(f"kinema: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("kinema: interrupted", file=sys.stderr)
        return 130
    finally:
        if getattr(args, "precision", None):  # main() called in-process (tests) leaves the environment as it was
            if before is None:
                os.environ.pop("KINEMA_PRECISION", None)
            else:
                os.environ["KINEMA_PRECISION"] = before
    return int(result or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
