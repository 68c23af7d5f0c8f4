"""The fuzz harness's mutators: how a case's input is made from the seeded ``rng`` alone, so a
seed replays it. :func:`mutate` damages bytes of any format (flips, overwrites, truncation);
:func:`crafted_session` writes a session file that is structurally valid but crafted to read
elsewhere, exhaust memory or confuse types; :func:`datagram` bends a CRTP datagram for the UDP
simulator. The targets that feed them to the code under test: :mod:`tests.fuzz.targets`.
"""

from __future__ import annotations

import random
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
    some crafted files point back at) edited in place at ``path``."""
    import h5py
    import numpy as np

    path.write_bytes(clean)
    how = rng.randrange(9)
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
