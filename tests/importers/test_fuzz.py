"""Fuzz: mutated cfclient CSVs and uSD logs through ``groundstation import``.

Each run tries 200 cases from a seed that changes daily (``IMPORT_FUZZ_SEED`` overrides it; the
seed is printed and named in every failure). Every case must end in a readable, cleanly closed
session or in one ``error:`` line with exit 2 and nothing left in the output folder; never a
traceback. Bigger campaigns: ``.venv/bin/python -m tests.importers.fuzz --cases 5000``.
"""

from __future__ import annotations

import os

from tests.importers.fuzz import case, date_seed

CASES = 200
HANG_S = 30.0
"""Far above any case (the slowest takes well under a second); catches a hang or quadratic
blow-up (60 000 columns took 165 s before the column limit), not a slow machine."""


def test_importers_survive_mutated_logs(tmp_path):
    seed = int(os.environ.get("IMPORT_FUZZ_SEED", date_seed()))
    print(f"import fuzz seed {seed} (IMPORT_FUZZ_SEED={seed} repeats it)")
    problems, imported = [], 0
    for i in range(CASES):
        src, outcome = case(seed, i, tmp_path)
        if outcome.problem or outcome.seconds > HANG_S:
            problems.append(f"case {i} ({src.name}, {outcome.seconds:.1f} s): {outcome.problem}")
        imported += outcome.ok
    assert not problems, f"seed {seed}: " + "; ".join(problems[:5])
    assert 0 < imported < CASES  # the mutations both pass and fail: the check has teeth
