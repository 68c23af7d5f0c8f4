"""Progress of sweep and batch: a bar with ETA on a terminal, ten plain lines otherwise."""

from __future__ import annotations

import io

from sysid.cli_progress import progress


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_plain_lines_every_tenth_when_not_a_terminal() -> None:
    out = io.StringIO()
    with progress("sweep", total=200, stream=out) as update:
        for done in range(1, 201):
            update(done)
        update(200)  # a repeated final count prints nothing more
    lines = out.getvalue().splitlines()
    assert len(lines) == 10
    assert lines[0].startswith("sweep: 20/200 (10 %)") and "eta" in lines[0]
    assert lines[-1].startswith("sweep: 200/200 (100 %)") and lines[-1].endswith("done")


def test_work_that_fails_does_not_say_done() -> None:
    out = io.StringIO()
    try:
        with progress("sweep", total=10, stream=out) as update:
            update(10)
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        pass
    assert "done" not in out.getvalue()


def test_a_bar_with_eta_on_a_terminal_and_nothing_when_quiet() -> None:
    out = _Tty()
    with progress("batch", total=4, stream=out) as update:
        update(2)
    text = out.getvalue()
    assert "batch" in text and "2/4" in text and "eta" in text and "\n" in text
    quiet = io.StringIO()
    with progress("batch", total=4, stream=quiet, quiet=True) as update:
        update(4)
    assert quiet.getvalue() == ""


def test_work_that_grows_counts_against_the_new_total() -> None:
    """A selection whose grid grows (sysid.growth) reports a larger total: the plain lines
    follow it, and the end is the new total, not the first."""
    out = io.StringIO()
    with progress("sweep", total=100, stream=out) as update:
        for done in range(1, 101):
            update(done, 100)
        for done in range(101, 151):
            update(done, 150)
    lines = out.getvalue().splitlines()
    assert lines[-1].startswith("sweep: 150/150 (100 %)") and lines[-1].endswith("done")
    assert not any(line.startswith("sweep: 150/100") for line in lines)
    # "done" only once the work has ended, not at the first total's 100 % (first-day audit:
    # "264/264 (100 %) done", then "265/315 (84 %)")
    assert [line for line in lines if line.endswith("done")] == [lines[-1]]
    bar = _Tty()
    with progress("sweep", total=10, stream=bar) as update:
        update(12, 20)
    assert "12/20" in bar.getvalue()
    with progress("sweep", total=4, stream=io.StringIO(), quiet=True) as update:
        update(5, 8)  # quiet takes the same arguments


def test_a_long_unit_of_work_says_where_it_is_every_heartbeat() -> None:
    """A batch's group that takes minutes: not on a terminal, a line with the detail once the
    heartbeat passed without a line (counted on the given clock), none more often."""
    out, now = io.StringIO(), [0.0]
    with progress("batch", total=4, stream=out, heartbeat_s=30.0, clock=lambda: now[0]) as update:
        for k in range(1, 101):  # group 1's models, one a second
            now[0] = float(k)
            update(detail=f"a0: {k}/100 models")
        update(1)
    lines = out.getvalue().splitlines()
    assert lines[:3] == ["batch: 0/4 (0 %), 30 s, a0: 30/100 models",
                         "batch: 0/4 (0 %), 60 s, a0: 60/100 models",
                         "batch: 0/4 (0 %), 90 s, a0: 90/100 models"]
    assert lines[3].startswith("batch: 1/4 (25 %), 100 s, eta")
    tty = _Tty()
    with progress("batch", total=4, stream=tty) as update:
        update(detail="a0: 3/100 models")
    assert "batch (a0: 3/100 models)" in tty.getvalue()
