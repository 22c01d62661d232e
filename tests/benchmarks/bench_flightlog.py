"""Cost of the flight log, per message and per 120 Hz step of 6 vector channels.

Plain script (not collected by pytest): ``.venv/bin/python tests/benchmarks/bench_flightlog.py``.

Compares, on the same rows (widths of the sim loop's channels: truth 29, surfaces 6,
operating point 6, pilot 8, sensors 12, one 8-wide detector residual; smooth signals plus noise):

1. the buffering primitive a ``write()`` can use (numpy row copy vs bytes into a list),
2. ``mcap.writer.Writer`` (pure Python, one ``add_message`` per message),
3. ``foxglove-sdk`` (Rust core, one ``log`` per message, custom ros2msg schema),
4. :class:`fdi_sim.flightlog.FlightLogWriter` (bytes buffered, one numpy-built chunk per
   simulated second) with zstd, lz4 and no compression,
5. reading a 300 s log with :func:`read_log` against ``mcap`` ``iter_messages`` + ``struct``,
6. repairing that log cut in half.

Each writer flushes once per simulated second. Times are wall clock on whatever else the
machine is doing: run it twice and read the smaller numbers.
"""
from __future__ import annotations

import argparse
import os
import struct
import tempfile
import time
import timeit
from pathlib import Path

import numpy as np

from fdi_sim.flightlog import FlightLogWriter, read_log, repair_log
from fdi_sim.flightlog.records import VectorBlock, build_chunk
from fdi_sim.flightlog.schemas import CDR_LE_HEADER

WIDTHS = (29, 6, 6, 8, 12, 8)
RATE_HZ = 120


def make_rows(seconds: float, seed: int = 0) -> tuple[np.ndarray, list[np.ndarray]]:
    """Times and, per channel, an (n, width) array of smooth signals with a little noise."""
    rng = np.random.default_rng(seed)
    n = int(round(seconds * RATE_HZ))
    t = np.arange(n) / RATE_HZ
    rows = []
    for w in WIDTHS:
        freq = rng.uniform(0.05, 1.0, w)
        amp = rng.uniform(0.1, 100.0, w)
        rows.append(amp * np.sin(2 * np.pi * np.outer(t, freq)) + 1e-3 * amp * rng.standard_normal((n, w)))
    return t, rows


def bench_primitives() -> None:
    buf = np.zeros((256, 29))
    v = np.ones(29)
    vt = tuple(v.tolist())
    lst: list = []
    pack = struct.Struct("<29d").pack
    g = {"buf": buf, "v": v, "vt": vt, "lst": lst, "pack": pack}
    print("buffering primitives (29 float64), ns per call:")
    for stmt in ("buf[7] = v", "buf[7] = vt", "lst.append(v.tobytes())", "lst.append(pack(*vt))"):
        n = 200_000
        best = min(timeit.repeat(stmt, globals=g, number=n, repeat=5)) / n
        lst.clear()
        print(f"  {stmt:28s} {best * 1e9:7.0f}")


def _loop(t: np.ndarray, rows: list, writes: list, flush=None) -> None:
    """The sim loop's logging: per step one ``write(t_s, row)`` per channel, and ``flush()``
    when a step reaches a whole simulated second (the FlightLogWriter flushes itself)."""
    next_flush = 1.0
    for k in range(len(t)):
        tk = float(t[k])
        if flush is not None and tk >= next_flush:
            flush()
            next_flush += 1.0
        for write, r in zip(writes, rows):
            write(tk, r[k])


def _ros2msg(width: int) -> bytes:
    return "".join(f"float64 f{j}\n" for j in range(width + 1)).encode()


def _cdr(t_s: float, v: np.ndarray, _d=struct.Struct("<d").pack) -> bytes:
    return CDR_LE_HEADER + _d(t_s) + v.tobytes()


def bench_mcap(path: Path, t: np.ndarray, rows: list[np.ndarray]) -> float:
    from mcap.writer import CompressionType, Writer
    t0 = time.perf_counter()
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start()
        writes = []
        for i, width in enumerate(WIDTHS):
            cid = w.register_channel(f"/c{i}", "cdr", w.register_schema(f"bench/msg/V{i}", "ros2msg", _ros2msg(width)))

            def write(t_s: float, v: np.ndarray, cid: int = cid) -> None:
                ns = round(t_s * 1e9)
                w.add_message(cid, ns, _cdr(t_s, v), ns)
            writes.append(write)
        _loop(t, rows, writes, w.flush)
        w.finish()
    return time.perf_counter() - t0


def bench_foxglove(path: Path, t: np.ndarray, rows: list[np.ndarray]) -> float | None:
    try:
        import foxglove
        from foxglove.mcap import MCAPCompression, MCAPWriteOptions
    except ImportError:
        return None
    if path.exists():
        path.unlink()
    ctx = foxglove.Context()
    t0 = time.perf_counter()
    w = foxglove.open_mcap(str(path), context=ctx, writer_options=MCAPWriteOptions(
        compression=MCAPCompression.Zstd, compression_threads=0))
    w.write_metadata("scenario", {"name": "bench"})
    writes = []
    for i, width in enumerate(WIDTHS):
        schema = foxglove.Schema(name=f"bench/msg/V{i}", encoding="ros2msg", data=_ros2msg(width))
        log = foxglove.Channel(f"/c{i}", schema=schema, message_encoding="cdr", context=ctx).base.log

        def write(t_s: float, v: np.ndarray, log=log) -> None:
            log(_cdr(t_s, v), round(t_s * 1e9))
        writes.append(write)
    _loop(t, rows, writes, w.flush)
    w.close()
    return time.perf_counter() - t0


def bench_loop_only(path: Path, t: np.ndarray, rows: list[np.ndarray]) -> float:
    """The same loop calling a do-nothing write: the cost every row above includes."""
    def write(t_s: float, values: np.ndarray) -> None:
        pass
    path.write_bytes(b"")
    t0 = time.perf_counter()
    _loop(t, rows, [write] * len(WIDTHS))
    return time.perf_counter() - t0


def bench_flightlog(path: Path, t: np.ndarray, rows: list, compression: str | None) -> float:
    """FlightLogWriter; ``rows`` per channel: (n, width) arrays, or lists of tuples as the sim
    loop passes for the pilot commands and the operating point."""
    t0 = time.perf_counter()
    with FlightLogWriter(path, metadata={"scenario": {"name": "bench"}}, compression=compression) as w:
        chans = [w.add_vector_channel(f"/c{i}", f"bench/msg/V{i}", ["t_s"] + [f"f{j}" for j in range(width)])
                 for i, width in enumerate(WIDTHS)]
        _loop(t, rows, [c.write for c in chans])
    return time.perf_counter() - t0


def bench_compression(t: np.ndarray, rows: list[np.ndarray]) -> None:
    """Compress one one-second chunk of the rows at several settings."""
    import lz4.frame
    import zstandard

    n = RATE_HZ
    blocks = [VectorBlock(i + 1, 0, t[:n], r[:n]) for i, r in enumerate(rows)]
    raw = bytes(build_chunk(blocks).records)
    t0 = time.perf_counter()
    for _ in range(20):
        build_chunk(blocks)
    build_us = (time.perf_counter() - t0) / 20 * 1e6
    print(f"\none chunk (1 s, {len(raw)} bytes): build_chunk {build_us:.0f} us; compression:")
    codecs = [(f"zstd level {lvl}", zstandard.ZstdCompressor(level=lvl).compress) for lvl in (-5, -1, 1, 3)]
    codecs.append(("lz4 frame", lz4.frame.compress))
    for name, fn in codecs:
        out = fn(raw)
        t0 = time.perf_counter()
        for _ in range(20):
            fn(raw)
        el = (time.perf_counter() - t0) / 20
        print(f"  {name:12s} {el * 1e6:7.0f} us/chunk ({el / n * 1e6:5.2f} us/step)  ratio {len(out) / len(raw):.3f}")


def bench_read(path: Path) -> None:
    from mcap.reader import make_reader
    t0 = time.perf_counter()
    log = read_log(path)
    el = time.perf_counter() - t0
    n = sum(log.message_counts.values())
    print(f"read_log: {n} messages in {el:.3f} s ({el / n * 1e6:.2f} us/message)")
    t0 = time.perf_counter()
    m = 0
    with open(path, "rb") as f:
        for _s, _c, msg in make_reader(f).iter_messages(log_time_order=False):
            struct.unpack_from(f"<{(len(msg.data) - 4) // 8}d", msg.data, 4)
            m += 1
    el2 = time.perf_counter() - t0
    print(f"mcap iter_messages + struct: {m} messages in {el2:.3f} s ({el2 / m * 1e6:.2f} us/message)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="simulated seconds written per writer")
    ap.add_argument("--read-seconds", type=float, default=300.0, help="length of the log to read back")
    args = ap.parse_args()
    bench_primitives()
    t, rows = make_rows(args.seconds)
    n_steps, n_msg = len(t), len(t) * len(WIDTHS)
    print(f"\nwriting {args.seconds:g} s at {RATE_HZ} Hz, {len(WIDTHS)} channels of {WIDTHS} values "
          f"({n_msg} messages), flush every simulated second:")
    print(f"  {'writer':28s} {'us/message':>10s} {'us/step':>9s} {'MB':>7s}")
    with tempfile.TemporaryDirectory() as tmp:
        runs = [("loop only (no-op write)", lambda p: bench_loop_only(p, t, rows)),
                ("mcap.writer.Writer zstd", lambda p: bench_mcap(p, t, rows)),
                ("foxglove-sdk zstd", lambda p: bench_foxglove(p, t, rows))]
        runs += [(f"FlightLogWriter {c or 'none'}", lambda p, c=c: bench_flightlog(p, t, rows, c))
                 for c in ("zstd", "lz4", None)]
        tuples = [[tuple(x) for x in r.tolist()] for r in rows]
        runs.append(("FlightLogWriter zstd, tuples", lambda p: bench_flightlog(p, t, tuples, "zstd")))
        for name, fn in runs:
            p = Path(tmp) / "w.mcap"
            el = fn(p)
            if el is None:
                print(f"  {name:28s} (not installed)")
                continue
            print(f"  {name:28s} {el / n_msg * 1e6:10.2f} {el / n_steps * 1e6:9.2f} "
                  f"{os.path.getsize(p) / 1e6:7.2f}")
        bench_compression(t, rows)
        tr, rr = make_rows(args.read_seconds, seed=1)
        big = Path(tmp) / "big.mcap"
        bench_flightlog(big, tr, rr, "zstd")
        print(f"\n{args.read_seconds:g} s log: {os.path.getsize(big) / 1e6:.2f} MB")
        bench_read(big)
        cut = Path(tmp) / "cut.mcap"
        cut.write_bytes(big.read_bytes()[: os.path.getsize(big) // 2])
        t0 = time.perf_counter()
        rep = repair_log(cut)
        print(f"repair of the log cut in half: {rep.messages_recovered} messages up to "
              f"t = {rep.last_t_s:.2f} s in {time.perf_counter() - t0:.3f} s")


if __name__ == "__main__":
    main()
