"""Wall time of the studio's "Try it" at its default and largest settings, for four-rooms and PinBall.

One run of :func:`torchrl_subgoal.studio.training.try_pattern` (HRS-D, its default, and the
unshaped learner, both on the fused engine, one torch thread) with a shipped
participant's pattern: four-rooms participant 7, PinBall participant 1 on the
simple map (pick-and-place has no "Try it"). The kernels are compiled (and cached) by a
tiny run first. Settings are the bounds of
:func:`torchrl_subgoal.studio.domains.default_domains`.

Usage::

    python benchmarks/studio_try_it.py           # the table of docs/studio.md (about 2 minutes)
    python benchmarks/studio_try_it.py --quick   # the default settings only
"""

from __future__ import annotations

import argparse
import time
from importlib.resources import files

import torch

from torchrl_subgoal import load_patterns
from torchrl_subgoal.studio.domains import default_domains
from torchrl_subgoal.studio.training import TrySettings, try_pattern

PATTERNS = {
    "four_rooms": ("four_rooms_participants.yaml", "participant_7"),
    "pinball": ("pinball_participants.yaml", "participant_1"),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="the default settings only, not the largest")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print("| domain | episodes x learners | seconds |\n|---|---|---|")
    studio = default_domains()
    for name, (file, pattern) in PATTERNS.items():  # the domains whose Try it runs (not pick-and-place)
        domain = studio[name]
        series = load_patterns(str(files("torchrl_subgoal") / "domains" / name / file))[pattern]
        map_ = next(iter(domain.maps), None)
        try_pattern(name, series, TrySettings(1, 1, max_steps=100), map=map_)  # compile
        limits = domain.limits
        for which in ("default",) if args.quick else ("default", "high"):
            episodes, learners = getattr(limits["episodes"], which), getattr(limits["learners"], which)
            start = time.perf_counter()
            try_pattern(name, series, TrySettings(episodes, learners), map=map_)
            print(f"| {name} ({which}) | {episodes} x {learners} | {time.perf_counter() - start:.1f} |", flush=True)


if __name__ == "__main__":
    main()
