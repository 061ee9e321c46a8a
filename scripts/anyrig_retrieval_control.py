"""`kinema evaluate-anyrig` with every prompt blank: the control for its caption retrieval.

    python scripts/anyrig_retrieval_control.py --model creatures --data cache/quat20rm --splits val test \
        --clips 4 --steps 20 --probe-seconds 0 --threads 1 --out out/eval_blank.json

Takes exactly the arguments of `kinema evaluate-anyrig` and runs it with every generation asked for the
empty prompt; everything else (cases, seeds, the joint target each case takes from its clip) is the same.
Retrieval hits that remain come from the targets, not the text: compare the "retrieval hits" of the two
reports (the creatures card, stop 49).
"""

from __future__ import annotations

import sys

from kinema.cli import main
from kinema.pipeline.base import MotionPipeline

_generate = MotionPipeline.generate


def _blank_prompt(self, request=None, /, **kwargs):
    return _generate(self, "", **kwargs)


if __name__ == "__main__":
    MotionPipeline.generate = _blank_prompt
    sys.exit(main(["evaluate-anyrig", *sys.argv[1:]]))
