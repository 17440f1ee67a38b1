"""Writers of small synthetic radar files, straight from the format descriptions.

Every sample encodes its place (see tests/data/README.md), so readers are checked
on exact values. These writers share no code with gpr3d's readers.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np


def expected_values(n_traces, n_samples, n_channels=1, bits=16):
    """(n_channels, n_traces, n_samples) int64 signed values the makers store."""
    tr = np.arange(n_traces)[None, :, None]
    s = np.arange(n_samples)[None, None, :]
    ch = np.arange(n_channels)[:, None, None]
    if bits == 8:
        return (tr + 2 * s + 40 * ch) % 100 - 50 + 0 * ch
    if bits == 16:
        return tr * 100 + s % 97 + ch * 10000 - 20000
    return tr * 100000 + s * 10 + ch


def write_dzt(path, n_traces=7, n_samples=64, n_channels=1, bits=16, range_ns=20.0, spm=100.0, sps=50.0,
              eps_r=9.0, antennas=("5103",), rh_data=None, extra_bytes=0):
    """A DZT file with ``n_channels`` 1024-byte headers; data at 1024 * rh_data (default n_channels)."""
    rh_data = n_channels if rh_data is None else rh_data
    head = bytearray(1024 * n_channels)
    for ch in range(n_channels):
        h = bytearray(1024)
        struct.pack_into("<HHHHH", h, 0, 0x00FF + 0x100 * ch, rh_data, n_samples, bits,
                         {8: 0x80, 16: 0x8000, 32: 0}[bits] & 0xFFFF)
        struct.pack_into("<5f", h, 10, sps, spm, 0.0, 0.0, range_ns)
        # 2021-06-15 10:20:30 packed: sec/2, min, hour, day, month, year-1980
        v = (15 // 1) | (20 << 5) | (10 << 11) | (15 << 16) | (6 << 21) | ((2021 - 1980) << 25)
        struct.pack_into("<I", h, 32, v)
        struct.pack_into("<H", h, 52, n_channels)
        struct.pack_into("<f", h, 54, eps_r)
        name = antennas[ch % len(antennas)].encode()
        h[98 : 98 + len(name)] = name
        head[1024 * ch : 1024 * (ch + 1)] = h
    offset = 1024 * rh_data if rh_data < 1024 else 1024 * n_channels
    vals = expected_values(n_traces, n_samples, n_channels, bits)  # (ch, tr, s)
    zero = {8: 128, 16: 32768, 32: 0}[bits]
    dtype = {8: "<u1", 16: "<u2", 32: "<i4"}[bits]
    scans = np.transpose(vals, (1, 0, 2)) + zero  # (tr, ch, s)
    body = scans.astype(dtype).tobytes()
    with open(path, "wb") as f:
        f.write(bytes(head))
        f.write(b"\x00" * (offset - len(head)))
        f.write(body)
        f.write(b"\x07" * extra_bytes)
    return Path(path)


def write_dt1(stem, n_traces=6, n_points=50, window_ns=100.0, step=0.25, units="m", freq=250.0, sep=0.4,
              hd_traces=None, bad_trace=None, bits=16):
    """A pulseEKKO DT1/HD pair (16- or 32-bit samples, as the trace header's bytes per point says); returns the
    DT1 path."""
    stem = Path(stem)
    hd = (
        "1234\nData Collected with test maker\n2020-01-02\n"
        f"NUMBER OF TRACES   = {n_traces if hd_traces is None else hd_traces}\n"
        f"NUMBER OF PTS/TRC  = {n_points}\nTIMEZERO AT POINT  = 3.5\nTOTAL TIME WINDOW  = {window_ns}\n"
        f"STARTING POSITION  = 0.0\nFINAL POSITION     = {step * (n_traces - 1)}\nSTEP SIZE USED     = {step}\n"
        f"POSITION UNITS     = {units}\nNOMINAL FREQUENCY  = {freq}\nANTENNA SEPARATION = {sep}\n"
        "NUMBER OF STACKS   = 4\n"
    )
    stem.with_suffix(".HD").write_text(hd)
    vals = expected_values(n_traces, n_points, 1, bits)[0]
    with open(stem.with_suffix(".DT1"), "wb") as f:
        for i in range(n_traces):
            h = np.zeros(32, dtype="<f4")
            h[0], h[1], h[2], h[5], h[6], h[7] = i + 1, i * step, n_points, bits // 8, window_ns, 4
            if bad_trace == i:
                h[2] = n_points + 1
            h[23] = 1000.0 + 0.5 * i
            f.write(h.tobytes())
            f.write(vals[i].astype("<i2" if bits == 16 else "<i4").tobytes())
    return stem.with_suffix(".DT1")


def write_rd3(stem, n_traces=5, n_samples=40, fs_mhz=2000.0, window_ns=None, last=None, interval=0.05):
    """A MALA RD3/RAD pair; returns the RD3 path."""
    stem = Path(stem)
    rad = (f"SAMPLES:{n_samples}\nFREQUENCY:{fs_mhz}\nDISTANCE INTERVAL: {interval}\n"
           f"ANTENNAS:800 shielded\nANTENNA SEPARATION: 0.14\n"
           f"TIMEWINDOW:{window_ns if window_ns is not None else n_samples / fs_mhz * 1000}\n"
           f"LAST TRACE:{n_traces if last is None else last}\nSTACKS:8\n")
    stem.with_suffix(".rad").write_text(rad)
    vals = expected_values(n_traces, n_samples, 1, 16)[0]
    stem.with_suffix(".rd3").write_bytes(vals.astype("<i2").tobytes())
    return stem.with_suffix(".rd3")


def write_gprmax3_out(path, n_traces=4, iterations=30, dt=1e-11, rxsteps=(2, 0, 0), dl=(0.002, 0.002, 0.002),
                      srcsteps=None):
    """A merged gprMax 3 style .out file (no trace_metadata): positions follow the step attributes (``srcsteps``
    defaults to ``rxsteps``)."""
    import h5py

    with h5py.File(path, "w") as f:
        f.attrs["gprMax"] = "3.1.7"
        f.attrs["Title"] = "maker"
        f.attrs["Iterations"] = iterations
        f.attrs["dt"] = dt
        f.attrs["dx_dy_dz"] = dl
        f.attrs["nx_ny_nz"] = (100, 80, 1)
        f.attrs["nrx"] = 1
        f.attrs["nsrc"] = 1
        f.attrs["srcsteps"] = rxsteps if srcsteps is None else srcsteps
        f.attrs["rxsteps"] = rxsteps
        f.create_group("srcs/src1").attrs.update({"Position": (0.02, 0.1, 0.0), "Type": "HertzianDipole"})
        rx = f.create_group("rxs/rx1")
        rx.attrs["Position"] = (0.06, 0.1, 0.0)
        rx.attrs["Name"] = "rx1"
        vals = expected_values(n_traces, iterations, 1, 32)[0].astype(float)
        for comp in ("Ex", "Ey", "Ez", "Hx", "Hy", "Hz"):
            rx.create_dataset(comp, data=vals.T * (1.0 if comp == "Ez" else 0.5))
    return Path(path)
