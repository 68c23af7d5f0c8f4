"""The fuzz harness's mutators: how a case's input is made from the seeded ``rng`` alone, so a
seed replays it. :func:`mutate` damages bytes of any format (flips, overwrites, truncation);
:func:`crafted_session` writes a session file that is structurally valid but crafted to read
elsewhere, exhaust memory or confuse types; :func:`datagram` bends a CRTP datagram for the UDP
simulator; :func:`plan_text` bends a flight plan's TOML. The targets that feed them to the code
under test: :mod:`tests.fuzz.targets`.
"""

from __future__ import annotations

import random
import re
import struct
from pathlib import Path


def mutate(rng: random.Random, data: bytes) -> bytes:
    """``data`` with a few bytes flipped, a range overwritten, the tail cut off, or a byte of
    the first 4 kB (where most HDF5 object headers live) set at random."""
    b = bytearray(data)
    how = rng.random()
    if how < 0.5:  # a few flipped bytes, anywhere
        for _ in range(rng.choice([1, 1, 2, 4, 16])):
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(8) if rng.random() < 0.5 else rng.randrange(1, 256)
    elif how < 0.7:  # a range overwritten
        i = rng.randrange(len(b))
        n = rng.randrange(1, 64)
        b[i:i + n] = rng.choice([bytes(n), b"\xff" * n, rng.randbytes(n)])
    elif how < 0.85:  # truncated
        del b[rng.randrange(len(b)):]
    else:  # a metadata byte: in the first 4 kB most objects' headers live
        i = rng.randrange(min(4096, len(b)))
        b[i] = rng.randrange(256)
    return bytes(b)


def crafted_session(rng: random.Random, work: Path, path: Path, clean: bytes) -> None:
    """A structurally valid file crafted to read elsewhere, exhaust memory or confuse types:
    ``clean`` (the session :mod:`tests.fuzz.targets` writes as ``work/base-clean.h5``, which
    some crafted files point back at) edited in place at ``path``; a quarter of them are
    :func:`_crafted_text_and_types` (fields and attributes retyped, markup in the text)."""
    import h5py
    import numpy as np

    path.write_bytes(clean)
    how = rng.randrange(12)
    if how >= 9:
        _crafted_text_and_types(rng, path, how - 9)
        return
    with h5py.File(path, "a") as f:
        if how == 0:  # external storage: another file's bytes as data
            secret = work / "secret.bin"
            secret.write_bytes(b"root:x:0:0:root:/root:/bin/bash\n" * 8)
            del f["gyro/data"]
            f["gyro"].create_dataset("data", shape=(4,), dtype=f["acc/data"].dtype,
                                     external=[(str(secret), 0, h5py.h5f.UNLIMITED)])
        elif how == 1:
            f["stolen"] = h5py.ExternalLink(str(work / "base-clean.h5"), "/gyro")
        elif how == 2:
            f["loop"] = h5py.SoftLink("/loop")
        elif how == 3:  # a virtual dataset
            layout = h5py.VirtualLayout(shape=(4,), dtype=f["acc/data"].dtype)
            layout[:] = h5py.VirtualSource(str(work / "base-clean.h5"), "acc/data", shape=(4,))
            del f["acc/data"]
            f["acc"].create_virtual_dataset("data", layout)
        elif how == 4:  # a huge declared shape with nothing stored
            dt = f["acc/data"].dtype
            del f["acc/data"]
            f["acc"].create_dataset("data", shape=(rng.choice([2**28, 2**40]),), dtype=dt,
                                    chunks=(64,), maxshape=(None,))
        elif how == 5:  # wrong dtypes
            del f["events/data"]
            f["events"].create_dataset("data", data=rng.choice([
                np.arange(10.0), np.zeros(3, dtype=[("host_time", "S4")]),
                np.zeros((3, 3), dtype=[("host_time", "f8")]),
                np.array([(0.0, "a")], dtype=[("host_time", "f8"),
                                              ("text", h5py.string_dtype())])]))
        elif how == 6:  # deep JSON in the summary
            f.attrs["summary"] = "[" * 100000 + "]" * 100000
        elif how == 7:
            f.attrs["schema_version"] = rng.choice([-1, 0, 2**40, 1.5, "1", np.array([1, 2])])
        else:  # wrongly typed attributes
            f.attrs["closed_cleanly"] = np.array([1, 2])
            f["gyro"].attrs["period_s"] = rng.choice(["fast", -1.0, 0.0])
            f["gyro/data"].attrs["units"] = 7


MARKUP = ("[/x]", "[/]", "[bold]", "[link=file:///etc/passwd]x[/link]", "[red", "\\[/x]")
"""Text that rich reads as markup (a closing tag with nothing open raises MarkupError)."""


def _retyped(data, field: str, dtype, values):
    """Structured ``data`` with ``field`` of ``dtype``, holding ``values`` (the rest kept)."""
    import numpy as np

    out = np.zeros(data.shape, dtype=[(n, dtype if n == field else data.dtype.fields[n][0])
                                      for n in data.dtype.names])
    for n in data.dtype.names:
        out[n] = values if n == field else data[n]
    return out


def _renamed(data, field: str, name: str):
    """Structured ``data`` with ``field`` called ``name``."""
    return data.astype([(name if n == field else n, data.dtype.fields[n][0])
                        for n in data.dtype.names])


def _set(data, values: dict):
    """A copy of structured ``data`` with the fields of ``values`` set."""
    data = data.copy()
    for name, value in values.items():
        data[name] = value
    return data


def _rewrite(f, stream: str, fn, *args) -> None:
    """``stream``'s data replaced by ``fn(data, *args)``, its attributes kept."""
    old = f[stream]["data"]
    data, attrs = fn(old[()], *args), dict(old.attrs)
    del f[stream]["data"]
    new = f[stream].create_dataset("data", data=data, chunks=True, maxshape=(None,))
    for k, v in attrs.items():
        new.attrs[k] = v


def _crafted_text_and_types(rng: random.Random, path: Path, how: int) -> None:
    """The crafted files of review C: a standard stream's field of another type (a phase id of
    float NaN, a phase name of integers, an event level of floats, a setpoint of bytes),
    markup in the file's text (stream kinds, phase names and kinds, event text, uri, plan name),
    root attributes of arrays; often two at once."""
    import contextlib

    import h5py

    with h5py.File(path, "a") as f:
        for _ in range(rng.choice([1, 1, 2])):
            # a second edit that the first made moot (a phase name retyped, then marked up)
            with contextlib.suppress(ValueError, TypeError):
                _craft(rng, f, how)
            how = rng.randrange(3)


def _craft(rng: random.Random, f, how: int) -> None:
    """One edit of :func:`_crafted_text_and_types` on the open file ``f``."""
    import h5py
    import numpy as np

    if how == 0:  # a standard field retyped
        n_phases, n_events = len(f["phases/data"]), len(f["events/data"])
        stream, field, dtype, values = rng.choice([
            ("phases", "phase_id", "f8", np.full(n_phases, np.nan)),
            ("phases", "phase_id", "f8", np.full(n_phases, 1e300)),
            ("phases", "name", "i4", np.arange(n_phases)),
            ("phases", "kind", "f4", np.full(n_phases, np.inf)),
            ("events", "level", "f8", np.full(n_events, rng.choice([np.nan, 2.5]))),
            ("events", "text", "f8", np.full(n_events, np.nan)),
            ("events", "cont", "S2", np.full(n_events, b"1")),
            ("setpoints", rng.choice(["roll", "thrust", "phase_id", "tick"]), "S4",
             np.full(len(f["setpoints/data"]), b"x")),
            ("setpoints", "host_time", "i8", np.arange(len(f["setpoints/data"]))),
            ("gyro", "fw_time_ms", "f8",
             np.where(np.arange(len(f["gyro/data"])) % 50 == 0, np.nan, 1.0)),
            ("link", "quality", "S3", np.full(len(f["link/data"]), b"x"))])
        _rewrite(f, stream, _retyped, field, dtype, values)
    elif how == 1:  # markup where the file's text is shown
        text = rng.choice(MARKUP)
        where = rng.choice(["kind", "phase", "event", "uri", "plan", "field", "units"])
        if where == "kind":
            f[rng.choice(["gyro", "events", "phases", "link"])].attrs["kind"] = text
        elif where == "phase":
            _rewrite(f, "phases", _set, {rng.choice(["name", "kind"]): text.encode()})
        elif where == "event":
            _rewrite(f, "events", _set, {"text": text.encode(), "source": text.encode()})
        elif where == "field":
            _rewrite(f, "acc", _renamed, "y", text)
        elif where == "units":
            f["gyro/data"].attrs["units"] = [text] * 5
        else:
            f.attrs["uri" if where == "uri" else "plan_name"] = text
    else:  # root attributes of arrays
        for key in rng.sample(["uri", "plan_name", "start_time_iso", "start_time_ns",
                               "duration_s", "closed_cleanly", "summary", "params",
                               "phase_table", "firmware", "tag", "plan_text"],
                              rng.choice([1, 2, 4])):
            f.attrs[key] = rng.choice([np.arange(3), np.array([1.5, np.nan]),
                                       np.array(["a", "[/x]"], dtype=h5py.string_dtype()),
                                       np.zeros((2, 2)), np.array([], dtype="f8")])


def datagram(rng: random.Random) -> bytes:
    """Random bytes, a well-formed header on any service with bent arguments, a setpoint of
    garbage numbers, or a log block command with random ids, types and periods."""
    from groundstation.sim.crtp import crtp_header

    kind = rng.random()
    if kind < 0.2:  # random bytes, any length
        return rng.randbytes(rng.choice([0, 1, 2, 5, 31, 32, 200]))
    if kind < 0.7:  # a well-formed header on every service, arguments bent
        port = rng.choice([0, 2, 3, 4, 5, 6, 7, 8, 13, 14, 15])
        payload = bytes([rng.randrange(12)]) + struct.pack(
            "<H", rng.choice([0, 1, 2, 300, 0xFFFF])) + rng.randbytes(rng.randrange(0, 28))
        return bytes([crtp_header(port, rng.randrange(4))]) + payload[:30]
    if kind < 0.85:  # commander and generic setpoints with garbage numbers
        vals = [rng.choice([float("nan"), float("inf"), -1e30, 0.0, 25.0]) for _ in range(3)]
        return bytes([crtp_header(3, 0)]) + struct.pack("<fffH", *vals, rng.randrange(65536))
    # log block create/append/start with random ids, types and periods
    return bytes([crtp_header(5, 1), rng.randrange(8), rng.randrange(256)]) + rng.randbytes(
        rng.randrange(0, 29))


# ------------------------------------------------------------------------- flight plans

_ASSIGN = re.compile(r"^(\s*)([A-Za-z0-9_.\"' -]+?)\s*=\s*(.*)$")
"""A ``key = value`` line of a plan (the value with its trailing comment, if any)."""


def _huge_int(rng: random.Random) -> str:
    return rng.choice(["9223372036854775807", "-9223372036854775808", "0x7fffffffffffffff",
                       "1" + "0" * rng.choice([19, 40, 309, 400, 5000])])


def _odd_value(rng: random.Random) -> str:
    """A TOML value of another type, out of range, non-finite, huge, deep, long or unicode."""
    how = rng.randrange(9)
    if how == 0:  # another type
        return rng.choice(['"text"', "true", "false", "[1, 2]", "[]", "{}", "{ a = 1 }",
                           "1979-05-27", "07:32:00", "1979-05-27T07:32:00Z", '["hover", 1]',
                           "[[1], [2]]", '{ signal = "prbs" }'])
    if how == 1:  # out of range, negative, zero, tiny
        return rng.choice(["0", "-1", "-0.0", "-2.0", "0.05", "1e-320", "65536", "-65536",
                           "1e9", "1e308", "-1e308", "3600", "3600.1", "100000", "2", "24",
                           "25", "16777215", "16777216", "0.30000000000000004", "1.5"])
    if how == 2:
        return rng.choice(["nan", "+nan", "-nan", "inf", "+inf", "-inf", "1e400", "-1e400"])
    if how == 3:
        return _huge_int(rng)
    if how == 4:  # deep nesting: arrays or inline tables
        depth = rng.choice([20, 200, 2000, 20000])
        if rng.random() < 0.5:
            return "[" * depth + "1" + "]" * depth
        return "{ a = " * depth + "1" + " }" * depth
    if how == 5:  # very long string or array
        n = rng.choice([100, 1000, 100_000, 1_000_000])
        return rng.choice([f'"{"x" * n}"', "[" + ", ".join(["1"] * min(n, 100_000)) + "]"])
    if how == 6:  # unicode and escapes: newlines, control characters, separators
        return rng.choice(['"é ü 飞行"', r'"a\nb"', r'"line\rreturn"', r'"\u2028sep"', r'"\t"',
                           r'"\u0000nul"', '"🚁"', r'"\\"', "'''multi\nline'''", '""',
                           r'"hover\n"', r'"\"quoted\""'])
    if how == 7:  # a float where an integer belongs, or the reverse
        return rng.choice(["39000.5", "39000.0", "1e4", "10", "0.1", "2.5e1", "1_000"])
    return rng.choice(["-3600", "-0.1", "-1e9", "0"])  # negative durations and times


_PARAM_NAMES = ["pid_attitude.yaw_kd", "pid_rate.roll_kp", "stabilizer.estimator",
                "posCtlPid.thrustBase", "powerDist.idleThrust", "pm.lowVoltage",
                "flightmode.althold", "nogroup.noname", "a.b", "_x._y", "x9.y9",
                '"with space".name', '"a.b".c', 'group."a\\nb"', '"".name', "group.name.extra",
                "plain", '"飞".行', "group.\"\"", "g.n-dash", "g.1st"]


def _parameters_table(rng: random.Random) -> list[str]:
    """A ``[parameters]`` table with odd names and values (sometimes more than allowed)."""
    lines = ["", "[parameters]"]
    names = rng.sample(_PARAM_NAMES, rng.choice([0, 1, 2, 3, 8]))
    names += [f"g{k}.n{k}" for k in range(rng.choice([0, 0, 0, 33]))]  # more than allowed
    for name in names:
        value = (_odd_value(rng) if rng.random() < 0.3 else
                 rng.choice(["0.0", "0.35", "300", "-1", "256", "1.5", "3.5e38", "1e39",
                             "4294967296", "-2147483649", "65535", "2", "1", "0"]))
        lines.append(f"{name} = {value}")
    if rng.random() < 0.2:
        lines += ["[parameters.pid_attitude]", f"yaw_kd = {_odd_value(rng)}"]
    return lines


def _live_id_table(rng: random.Random) -> list[str]:
    keys = {"inputs": ['["motors"]', '["gyro"]', "[]", '["motors", "motors"]', '["a.b.c"]',
                       '["motor.m1", "motor.m2"]', "[1]", '"motors"'],
            "outputs": ['["gyro"]', '["gyro.x", "gyro.y", "gyro.z"]', '["motors.m1"]', "[]"],
            "order": ["8", "0", "200", "201", "99"], "past": ["60", "0", "1000", "1001"],
            "future": ["17", "1", "2", "1000"], "update_period": ["1.0", "0.05", "600", "nan"]}
    lines = ["", "[live_id]"]
    for key in rng.sample(sorted(keys), rng.randrange(len(keys) + 1)):
        value = _odd_value(rng) if rng.random() < 0.2 else rng.choice(keys[key])
        lines.append(f"{key} = {value}")
    return lines


def _prbs_extremes(rng: random.Random, lines: list[str]) -> None:
    """PRBS settings at their extremes, the same on every axis (so ``plan check`` compares the
    axes' seeds), sometimes in a long phase at a high setpoint rate: a huge schedule."""
    bits = rng.choice([2, 3, 16, 20, 23, 24, 24, 24, 0, 1, 25, 64])
    values = {"register_length": str(bits),
              "period": rng.choice(["16777215", "8388607", "3", "7", "4294967295", "0", "-1",
                                    _huge_int(rng)]),
              "clock_period": rng.choice(["1", "2", "1000", "36000", "0", "-1", _huge_int(rng)]),
              "seed": rng.choice(["1", "2", str((1 << bits) - 1), str(1 << bits), "0",
                                  str(rng.randrange(1, 1 << max(bits, 2)))])}
    keep = {"register_length", *rng.sample(sorted(values), rng.randrange(len(values)))}
    for i, line in enumerate(lines):
        m = _ASSIGN.match(line)
        if m and m.group(2) == "register_length" and "period" in keep and rng.random() < 0.5:
            lines[i] = f"period = {values['period']}"  # the register given by its period
        elif m and m.group(2) in keep:
            lines[i] = f"{m.group(1)}{m.group(2)} = {values[m.group(2)]}"
            if m.group(2) == "seed" and rng.random() < 0.5:  # each axis its own seed
                lines[i] = f"seed = {rng.randrange(1, 1 << max(bits, 2))}"
        elif m and m.group(2) == "duration" and rng.random() < 0.15:
            lines[i] = f"duration = {rng.choice(['3600', '1200', '600', '102.3'])}"
        elif m and m.group(2) == "setpoint_rate_hz" and rng.random() < 0.5:
            lines[i] = f"setpoint_rate_hz = {rng.choice(['100', '50', '10', '2'])}"


def _many_phases(rng: random.Random, lines: list[str]) -> None:
    """A hover phase repeated many times, each as long as a phase may be: hours of setpoints."""
    at = next((i for i, line in enumerate(lines) if line.strip() == "[[phase]]"), None)
    if at is None:
        return
    n = rng.choice([10, 100, 1000, 5000])
    rate = rng.choice(["10", "100"])
    duration = rng.choice(["3600", "600", "1"])
    first = next((i for i, line in enumerate(lines[at + 1:], at + 1)
                  if line.strip() == "[[phase]]"), len(lines))  # after the take-off
    lines[first:first] = [line for k in range(n) for line in (
        "[[phase]]", f'name = "hover-{k}"', 'kind = "hover"', f"duration = {duration}", "")]
    lines[:] = [f"setpoint_rate_hz = {rate}" if line.startswith("setpoint_rate_hz") else line
                for line in lines]


def plan_text(rng: random.Random, text: str) -> bytes:
    """A flight plan's TOML ``text`` bent the way a hand-edited or downloaded plan can be: values
    of other types, out of range, non-finite, huge, deep, long or unicode; keys deleted,
    duplicated or unknown; empty or swapped tables; ``[parameters]`` and ``[live_id]`` tables
    with odd entries; PRBS settings at their extremes; a huge schedule; then sometimes the
    bytes damaged (:func:`mutate`) or another line ending or encoding."""
    lines = text.splitlines()
    if rng.random() < 0.3:
        lines += _parameters_table(rng)
    if rng.random() < 0.15:
        lines += _live_id_table(rng)
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        assigns = [i for i, line in enumerate(lines) if _ASSIGN.match(line)
                   and not line.lstrip().startswith("#")]
        how = rng.randrange(14)
        if how >= 12 and assigns:  # a number nudged, often still valid
            i = rng.choice(assigns)
            m = _ASSIGN.match(lines[i])
            value = m.group(3).split("#")[0].strip()
            if re.fullmatch(r"-?\d{1,12}(\.\d+)?", value):
                f = rng.choice([0.5, 0.9, 0.99, 1.01, 1.1, 2.0, -1.0])
                new = str(int(int(value) * f)) if value.lstrip("-").isdigit() else (
                    f"{float(value) * f:.1f}")
                lines[i] = f"{m.group(1)}{m.group(2)} = {new}"
        elif how <= 2 and assigns:  # a value replaced
            i = rng.choice(assigns)
            m = _ASSIGN.match(lines[i])
            lines[i] = f"{m.group(1)}{m.group(2)} = {_odd_value(rng)}"
        elif how == 4 and assigns:  # a key deleted
            del lines[rng.choice(assigns)]
        elif how == 5 and lines:  # a line duplicated (duplicate key or table)
            i = rng.randrange(len(lines))
            lines.insert(i, lines[i])
        elif how == 6:  # an unknown key, a near miss or an odd one
            key = rng.choice(["amplitud", "durration", "kind2", "x", '"a\\nb"', '"ключ"',
                              '"' + "k" * 5000 + '"', "thrust_start", "signal", "name"])
            lines.insert(rng.randrange(len(lines) + 1), f"{key} = {_odd_value(rng)}")
        elif how == 7:  # an empty table or array of tables, or a table's header swapped
            headers = [i for i, line in enumerate(lines) if line.lstrip().startswith("[")]
            if headers and rng.random() < 0.5:
                i = rng.choice(headers)
                name = lines[i].split("#")[0].strip().strip("[]")
                lines[i] = rng.choice([f"[[{name}]]", f"[{name}]", f"[{name}.extra]",
                                       "[phase]", "[[vehicle]]", "[phase.roll]"])
            else:
                lines.insert(rng.randrange(len(lines) + 1), rng.choice(
                    ["[altitude_hold]", "[live_id]", "[parameters]", "[safety]", "[[phase]]",
                     "[vehicle]", "[phase.pitch]", "[parameters.pid_attitude]", "[x.y.z]"]))
        elif how == 8:
            _prbs_extremes(rng, lines)
        elif how == 9 and rng.random() < 0.3:
            _many_phases(rng, lines)
        elif how == 3:  # a PRBS at its extremes, a second time
            _prbs_extremes(rng, lines)
        elif how == 10:  # a whole axis as a non-table, or an inline table of odd contents
            axis = rng.choice(["roll", "pitch", "yaw_rate", "thrust"])
            lines.insert(rng.randrange(len(lines) + 1), f"{axis} = " + rng.choice(
                ["5", '"prbs"', "{}", '{ signal = "step", amplitude = 1e9 }',
                 '{ signal = "chirp", amplitude = 5, f_start_hz = 1, f_end_hz = 1, '
                 'sweep = "log" }', '{ signal = "doublet", amplitude = -5, width = 0.1 }']))
        else:  # lines cut out: a table without its keys, a plan half written
            i = rng.randrange(len(lines) + 1)
            del lines[i:i + rng.randrange(1, 12)]
    out = "\n".join(lines) + "\n"
    if rng.random() < 0.1:
        out = out.replace("\n", rng.choice(["\r\n", "\r", "\u2028\n"]))
    data = out.encode("utf-8")
    if rng.random() < 0.1:
        data = rng.choice([b"\xef\xbb\xbf", b"\xff\xfe", b"\x89HDF\r\n\x1a\n"]) + data
    if rng.random() < 0.15:
        data = mutate(rng, data)
    return data
