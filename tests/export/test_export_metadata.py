"""``groundstation export --to csv|parquet``: both write ``metadata.json``, the same one, so an
imported log's ``time_base`` and ``source_problems`` reach Parquet users too."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from groundstation.cli import main
from groundstation.importers import usd_to_session
from groundstation.importers.to_session import TIME_BASE
from tests.importers.usd_logs import build_usd

EVENTS = [(1, "fixedFrequency", [("motor.m1", "H"), ("acc.z", "f")])]


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    """An imported uSD log with a problem: its CRC does not match (--allow-damaged)."""
    d = tmp_path_factory.mktemp("export-meta")
    data = build_usd(version=2, events=EVENTS, records=[(1, 10_000 * k, (k, 0.5 * k))
                                                        for k in range(20)])
    (d / "log02").write_bytes(data[:-1] + bytes([data[-1] ^ 1]))
    return usd_to_session(source=d / "log02", out=d / "log02.h5", allow_damaged=True)


def test_parquet_writes_the_metadata_json_csv_does(imported, tmp_path):
    """Parquet wrote no metadata.json: an imported log's time base and problems were lost."""
    pytest.importorskip("pyarrow")
    texts = {}
    for to in ("csv", "parquet"):
        out = tmp_path / to
        res = CliRunner().invoke(main, ["export", str(imported), "--to", to, "--out", str(out)])
        assert res.exit_code == 0, res.output
        files = sorted(p.name for p in out.iterdir())
        assert files == ["events." + to, "metadata.json", "motor+acc." + to, "phases." + to]
        assert res.output.strip() == f"wrote {len(files)} files to {out}"
        texts[to] = (out / "metadata.json").read_text()
    meta, csv_meta = json.loads(texts["parquet"]), json.loads(texts["csv"])
    for to, m in (("parquet", meta), ("csv", csv_meta)):  # which file holds which stream
        assert m.pop("stream_files") == {s: f"{s}.{to}" for s in ("motor+acc", "events",
                                                                   "phases")}
    assert meta == csv_meta
    assert meta["time_base"] == TIME_BASE
    [problem] = json.loads(meta["source_problems"])
    assert problem.startswith("CRC mismatch")
