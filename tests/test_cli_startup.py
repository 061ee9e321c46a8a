"""Building the command line's parser (every `kinema ...` call, `--help` included) loads no model code:
the pipelines, the networks and live streams are imported by the subcommand that runs them. A
module-level import of `kinema.generate` in `kinema/cli/bench_stream.py` once made every command load
both pipelines and kinema.stream (about 0.3 s of CPU per call)."""

from __future__ import annotations

import json
import subprocess
import sys

HEAVY = ("kinema.generate", "kinema.human", "kinema.anyrig", "kinema.model", "kinema.stream", "kinema.server.app")


def test_building_the_parser_imports_no_pipeline() -> None:
    probe = (
        "import json, sys\n"
        "from kinema.cli import build_parser\n"
        "build_parser()\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.startswith('kinema.'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    loaded = json.loads(out)
    assert "kinema.cli.generate" in loaded  # the probe did build the whole parser
    heavy = [m for m in loaded if m.startswith(HEAVY)]
    assert not heavy, f"the CLI's parser imports {heavy}: import them inside the subcommand's run()"
