"""sysid/model_io.py: every format round-trips a model exactly; a damaged or foreign model file,
or a FIFO in its place, is one ModelFileError line from the library and one ``error:`` line with
exit code 2 from the CLI; what ``save`` writes, ``load`` reads (the caps on size, text and
states are checked before writing).

Files crafted in each format: ``test_model_io_hdf5.py``, ``test_model_io_json.py``,
``test_model_io_mat.py``; the helpers they share: :mod:`tests.sysid.model_files`.
"""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from sysid import model_io
from sysid.errors import ModelFileError
from sysid.model import StateSpaceModel
from sysid.model_io import load, save
from tests.sysid.model_files import refused, sample_model


# ------------------------------------------------------------------------------ round trips
@pytest.mark.parametrize("suffix", [".h5", ".hdf5", ".json", ".mat"])
@pytest.mark.parametrize("noise", [True, False])
def test_round_trip_is_exact(tmp_path, suffix, noise):
    m = sample_model(noise=noise)
    back = load(save(m, tmp_path / f"m{suffix}"))
    for name in ("A", "B", "C", "D", "K", "noise_cov"):
        want, got = getattr(m, name), getattr(back, name)
        assert (got is None) if want is None else np.array_equal(got, want), name
    assert back.dt == m.dt
    assert (back.input_names, back.output_names) == (("thrust",), ("z",))
    assert (back.input_units, back.output_units) == (("N",), ("m",))
    assert back.provenance == m.provenance
    # a path as a string, as sysid.model.load_model takes it (it was an AttributeError: audit)
    assert np.array_equal(load(str(save(m, str(tmp_path / f"s{suffix}")))).A, m.A)


@pytest.mark.parametrize("suffix", [".h5", ".json", ".mat"])
def test_a_model_without_states_round_trips(tmp_path, suffix):
    m = StateSpaceModel(A=np.zeros((0, 0)), B=np.zeros((0, 1)), C=np.zeros((1, 0)),
                        D=np.array([[2.0]]), dt=0.5)
    back = load(save(m, tmp_path / f"m{suffix}"))
    assert back.n_states == 0 and back.D.tolist() == [[2.0]] and back.B.shape == (0, 1)


@pytest.mark.parametrize("suffix", [".h5", ".json", ".mat"])
def test_damaged_file_is_one_line(tmp_path, suffix):
    path = save(sample_model(), tmp_path / f"m{suffix}")
    path.write_bytes(path.read_bytes()[:40])
    refused(path, "not a readable sysid model")


def test_foreign_json_and_unknown_suffix(tmp_path):
    (tmp_path / "x.json").write_text('{"format": "other"}')
    refused(tmp_path / "x.json", "not a sysid model file")
    with pytest.raises(ModelFileError, match=r"suffix '\.txt' is unknown"):
        save(sample_model(), tmp_path / "m.txt")
    (tmp_path / "f.txt").write_text("a file")
    with pytest.raises(ModelFileError, match=r"f\.txt' is a file, not a folder"):
        save(sample_model(), tmp_path / "f.txt" / "m.h5")
    # a missing folder is made, as a session's writer makes its folder
    assert load(save(sample_model(), tmp_path / "no" / "m.h5")).n_states == sample_model().n_states


@pytest.mark.timeout(60)
@pytest.mark.parametrize("suffix", [".h5", ".json", ".mat"])
def test_a_fifo_as_the_model_is_refused_at_once(tmp_path, suffix):
    os.mkfifo(tmp_path / f"m{suffix}")  # reading it would block for ever
    refused(tmp_path / f"m{suffix}", "not a regular file")


# ------------------------------------------------- what save writes, load reads (the caps)
def test_a_model_of_the_most_states_round_trips_as_mat(tmp_path):
    """MAX_DIMENSION states with a Crazyflie's channels: 2 MB, well within MAX_FILE_BYTES."""
    n, rng = model_io.MAX_DIMENSION, np.random.default_rng(0)
    m = StateSpaceModel(A=rng.standard_normal((n, n)) * 0.01, B=rng.standard_normal((n, 4)),
                        C=rng.standard_normal((6, n)), D=np.zeros((6, 4)), dt=0.01)
    path = save(m, tmp_path / "m.mat")
    assert path.stat().st_size < model_io.MAX_FILE_BYTES / 4
    assert np.array_equal(load(path).A, m.A)


def test_the_ceiling_is_above_every_order_sysid_identifies():
    """A model the project makes is never refused for its order: live identification takes
    up to 200 states, the automatic grid grows to sysid.growth.MAX_ORDER, and
    ``identify --order`` stops at the ceiling itself (so no identification is spent on a model
    that save would then refuse)."""
    from click.testing import CliRunner

    from sysid.cli import main
    from sysid.growth import MAX_ORDER

    assert MAX_ORDER < model_io.MAX_DIMENSION and model_io.MAX_DIMENSION >= 200
    n = model_io.MAX_DIMENSION + 1
    res = CliRunner().invoke(main, ["identify", "flight.h5", "--order", str(n)])
    assert res.exit_code == 2 and f"{n} is not in the range 1<=x<={n - 1}" in res.stderr


@pytest.mark.timeout(60)
@pytest.mark.parametrize("suffix", [".h5", ".json", ".mat"])
def test_a_model_file_beyond_the_ceiling_is_one_line_naming_file_matrix_and_limit(tmp_path,
                                                                                suffix):
    """A crafted model of 2000 states took ``sysid compare`` over 25 s and its JSON export
    hundreds of MB (review); now one line, before any matrix is read (.h5) or used."""
    n = model_io.MAX_DIMENSION + 1
    m = sample_model()
    d = {**m.to_dict(), "A": np.eye(n) * 0.5, "B": np.ones((n, 1)), "C": np.ones((1, n)),
         "K": np.zeros((n, 1))}
    path = tmp_path / f"big{suffix}"
    if suffix == ".h5":
        import h5py

        save(m, path)
        with h5py.File(path, "a") as f:
            for name in "ABCK":
                del f[name]
                f[name] = d[name]
    elif suffix == ".json":
        path.write_text(json.dumps({k: v.tolist() if isinstance(v, np.ndarray) else v
                                    for k, v in d.items()}))
    else:
        import scipy.io

        save(m, path)
        mat = scipy.io.loadmat(path)
        mat.update({name: d[name] for name in "ABCK"})
        scipy.io.savemat(path, {k: v for k, v in mat.items() if not k.startswith("__")})
    msg = refused(path, rf"matrix 'A' .*(has shape \({n}, {n}\)|is {n} x {n}); a sysid model "
                  rf"(file )?has at most {n - 1} states, inputs and outputs")
    assert str(path) in msg


@pytest.mark.parametrize("suffix", [".mat", ".json"])
def test_a_file_larger_than_load_reads_is_not_written(tmp_path, monkeypatch, suffix):
    """At the cap the file is written and read back; one byte over, save refuses in one line
    naming the cap (and .h5, which has none) and writes nothing."""
    size = save(sample_model(), tmp_path / f"probe{suffix}").stat().st_size
    monkeypatch.setattr(model_io, "MAX_FILE_BYTES", size)
    back = load(save(sample_model(), tmp_path / f"m{suffix}"))
    assert back.provenance == sample_model().provenance
    monkeypatch.setattr(model_io, "MAX_FILE_BYTES", size - 1)
    path = tmp_path / f"n{suffix}"
    with pytest.raises(ModelFileError, match=rf"would be {size} bytes, more than the {size - 1} "
                       r"that load reads \(MAX_FILE_BYTES\); save the model as .h5") as err:
        save(sample_model(), path)
    assert "\n" not in str(err.value) and str(path) in str(err.value) and not path.exists()


@pytest.mark.parametrize("suffix", [".h5", ".mat"])
def test_a_text_longer_than_load_reads_is_not_written(tmp_path, suffix):
    """A provenance of MAX_TEXT_BYTES as JSON (the guard's MAX_ATTR_BYTES for .h5) is written
    and read back; one byte more, save refuses and points to JSON, which has no such cap."""
    fits = sample_model().replace(provenance={"x": "a" * (model_io.MAX_TEXT_BYTES - 9)})
    assert len(json.dumps(fits.provenance)) == model_io.MAX_TEXT_BYTES
    assert load(save(fits, tmp_path / f"m{suffix}")).provenance == fits.provenance
    over = fits.replace(provenance={"x": "a" * (model_io.MAX_TEXT_BYTES - 8)})
    path = tmp_path / f"n{suffix}"
    with pytest.raises(ModelFileError, match=r"its provenance text would be 1048577 bytes, "
                       r"more than the 1048576 that load reads \(MAX_TEXT_BYTES\); save the "
                       r"model as .json") as err:
        save(over, path)
    assert "\n" not in str(err.value) and not path.exists()
    assert load(save(over, tmp_path / "n.json")).provenance == over.provenance


@pytest.mark.parametrize("suffix", [".h5", ".mat", ".json"])
def test_more_states_than_load_reads_are_not_written(tmp_path, suffix):
    n = model_io.MAX_DIMENSION + 1
    m = StateSpaceModel(A=np.zeros((n, n)), B=np.zeros((n, 1)), C=np.zeros((1, n)), dt=0.01)
    path = tmp_path / f"m{suffix}"
    with pytest.raises(ModelFileError, match=rf"{n} states, more than the {n - 1} that load "
                       "reads"):
        save(m, path)
    assert not path.exists()




@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX file size limit (ulimit -f)")
def test_a_disk_without_room_is_one_line_and_no_file(tmp_path):
    """``ulimit -f`` (as a full disk or a quota): HDF5 failing inside its own writes crashed in
    its cleanup, pages of tracebacks and exit 139; now one line and no file, in every format
    (one process for the three: the limit holds for the rest of it)."""
    import subprocess
    import sys
    import textwrap

    targets = [str(tmp_path / f"m{suffix}") for suffix in (".h5", ".json", ".mat")]
    script = textwrap.dedent(f"""
        import resource
        from tests.sysid.model_files import sample_model
        from sysid.errors import ModelFileError
        from sysid.model_io import save
        resource.setrlimit(resource.RLIMIT_FSIZE, (256, 256))
        for target in {targets!r}:
            try:
                save(sample_model(), target)
            except ModelFileError as exc:
                print(exc)
        """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, cwd=os.path.dirname(os.path.dirname(os.path.dirname(
                              os.path.abspath(__file__)))))
    assert (done.returncode, done.stderr) == (0, ""), done.stderr[-2000:]
    assert done.stdout.splitlines() == [f"cannot write model file {t!r}: File too large"
                                        for t in targets]
    assert list(tmp_path.iterdir()) == []


def test_a_model_never_replaces_a_recorded_session(tmp_path):
    """``sysid identify ... --out flight.h5 --force`` replaced a (read-only) session file that
    was no input of the command with a model (CLI fuzz): refused before identifying, and by
    ``save`` for every other caller (batch, live id)."""
    from click.testing import CliRunner

    from sysid.cli import main
    from tests.sysid.flights import known_system, write_flight

    flight = write_flight(tmp_path / "f.h5", system=known_system(), seed=3, n=1500).path
    kept = write_flight(tmp_path / "kept.h5", system=known_system(), seed=4, n=1500).path
    before = kept.read_bytes()
    res = CliRunner().invoke(main, ["identify", str(flight), "--order", "4", "--past", "20",
                                    "--future", "10", "--out", str(kept), "--force"])
    assert res.exit_code == 2 and res.output.strip().splitlines() == [
        f"error: cannot write model file {str(kept)!r}: it holds a recorded flight session, "
        "which a model never replaces (not even with --force); choose another name"]
    with pytest.raises(ModelFileError, match="holds a recorded flight session"):
        save(sample_model(), kept)
    assert kept.read_bytes() == before
    save(sample_model(), tmp_path / "m.h5")
    save(sample_model(), tmp_path / "m.h5")  # a model file is replaced as before
    cut = tmp_path / "cut.h5"  # a session cut short (a crash, a copy): still a recorded flight
    cut.write_bytes(before[:50_000])
    with pytest.raises(ModelFileError, match="holds a recorded flight session"):
        save(sample_model(), cut)
    odd = tmp_path / "odd.h5"  # a schema attribute of a compound type: no TypeError escapes
    import h5py

    with h5py.File(odd, "w") as f:
        f.attrs["schema"] = np.zeros(1, dtype=[("a", "f8"), ("b", "i4")])
    save(sample_model(), odd)  # not a session: replaced


def test_sweep_refuses_a_session_as_its_model_before_sweeping(tmp_path, monkeypatch):
    """It refused only after running its whole grid (review)."""
    from click.testing import CliRunner

    import sysid.cli_sweep
    from sysid.cli import main
    from tests.sysid.flights import known_system, write_flight

    flight = write_flight(tmp_path / "f.h5", system=known_system(), seed=3, n=1500).path
    kept = write_flight(tmp_path / "kept.h5", system=known_system(), seed=4, n=1500).path

    def no_sweep(*_a, **_k):
        raise AssertionError("swept before refusing")

    monkeypatch.setattr(sysid.cli_sweep, "choose", no_sweep)
    res = CliRunner().invoke(main, ["sweep", str(flight), "--out", str(kept), "--force"])
    assert res.exit_code == 2 and "holds a recorded flight session" in res.output
