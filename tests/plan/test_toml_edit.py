"""Editing plan text with tomlkit (groundstation.plan.toml.set_keys): values set or added however
the table is written, every byte not edited kept, notes at the old comment's column."""

from __future__ import annotations

import tomllib

import pytest

from groundstation.errors import PlanError
from groundstation.plan import SHIPPED_PLANS_DIR
from groundstation.plan.toml import set_keys
from tests.plan.conftest import BASE

_ROLL = '[phase.roll]\nsignal = "prbs"\nregister_length = 5\namplitude = 20.0\nseed = 3\n'
_DOTTED = 'roll.signal = "prbs"\nroll.register_length = 5\nroll.amplitude = 20.0\n'
_TABLES = {
    "table": _ROLL.replace("seed = 3\n", "seed = 0x3  # hex\n"),
    "table-default": _ROLL.replace("seed = 3\n", ""),
    "inline": 'roll = { signal = "prbs", register_length = 5, amplitude = 20.0, seed = 3 }\n',
    "inline-default": 'roll = { signal = "prbs", register_length = 5, amplitude = 20.0 }  # x\n',
    "dotted": _DOTTED + "roll.seed = 3\n",
    "dotted-default": _DOTTED,
}


def _plan(table: str) -> str:
    return BASE.replace(_ROLL, table)


@pytest.mark.parametrize("path", sorted(SHIPPED_PLANS_DIR.glob("*.toml")), ids=lambda p: p.stem)
def test_no_edit_gives_the_text_back_byte_for_byte(path):
    text = path.read_text(encoding="utf-8")
    assert set_keys(text, edits=[]) == text
    assert set_keys(text, edits=[], mark="# design:") == text


@pytest.mark.parametrize("kind", _TABLES)
def test_values_are_set_or_added_however_the_table_is_written(kind):
    table = _TABLES[kind]
    text = _plan(table)
    new = set_keys(text, edits=[(("phase", 1, "roll", "seed"), 17, "why"),
                                (("phase", 1, "roll", "amplitude"), 27.5, "")],
                   mark="# design:")
    roll = tomllib.loads(new)["phase"][1]["roll"]
    assert (roll["seed"], roll["amplitude"], roll["register_length"]) == (17, 27.5, 5)
    old, edited = text.splitlines(), new.splitlines()
    changed = [ln for ln in edited if ln not in old]
    assert all(ln in edited for ln in old if "seed" not in ln and "amplitude" not in ln)
    note = "# design: seed: why" if "{" in table else "# design: why"
    assert sum(note in ln for ln in edited) == 1, new
    added = kind in ("table-default", "dotted-default")  # a line of its own
    assert len(changed) == (1 if "{" in table else 2) and len(edited) - len(old) == added


def test_notes_keep_the_comment_column_and_replace_the_old_comment():
    text = 'name = "a"       # the name\nseed = 1\n[vehicle]\nmax_roll_deg = 30.0\n'
    new = set_keys(text, edits=[(("name",), "abcd", "renamed"), (("seed",), 12, "moved")],
                   mark="# design:")
    assert new.splitlines()[:2] == ['name = "abcd"    # design: renamed',
                                    "seed = 12  # design: moved"]
    assert new.endswith('[vehicle]\nmax_roll_deg = 30.0\n')
    added = set_keys(text, edits=[(("vehicle", "max_pitch_deg"), 20.0, "")])
    assert tomllib.loads(added)["vehicle"] == {"max_roll_deg": 30.0, "max_pitch_deg": 20.0}
    assert added.startswith(text)  # appended to the last table, nothing above it touched


def test_a_missing_table_is_a_plan_error():
    with pytest.raises(PlanError, match=r"no table phase\[1\]\.pitch to set seed in"):
        set_keys(BASE, edits=[(("phase", 1, "pitch", "seed"), 3, "")])
    with pytest.raises(PlanError, match=r"no table phase\[9\]"):
        set_keys(BASE, edits=[(("phase", 9, "roll", "seed"), 3, "")])
