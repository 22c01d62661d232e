"""The cache's numpy-array entries (fdi_sim.training.cache.read_arrays / write_arrays, pca-v1's
training data): an entry reads back as written, and a damaged one is a miss to recompute, as a
damaged JSON entry is, never a crash."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from fdi_sim.training.cache import read_arrays, write_arrays

NAMES = ("train_u", "train_y")


def entry_arrays() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(7)
    return {"train_u": rng.normal(size=(50, 4)), "train_y": rng.normal(size=(50, 9))}


def test_an_array_entry_round_trips(tmp_path: Path) -> None:
    path = tmp_path / "cache" / "pca-train-abc.npz"  # the directory is made by the write
    written = entry_arrays()
    write_arrays(path, written)
    assert path.is_file()
    assert sorted(p.name for p in path.parent.iterdir()) == [path.name]  # the temporary file was renamed
    read = read_arrays(path, NAMES)
    assert read is not None and sorted(read) == sorted(NAMES)
    for nm in NAMES:
        assert read[nm].dtype == written[nm].dtype and np.array_equal(read[nm], written[nm])


def test_without_use_nothing_is_read_or_written(tmp_path: Path) -> None:
    path = tmp_path / "pca-train-abc.npz"
    write_arrays(path, entry_arrays(), use=False)
    assert not path.exists()
    write_arrays(path, entry_arrays())
    assert read_arrays(path, NAMES, use=False) is None


def truncated_npz() -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **entry_arrays())
    return buf.getvalue()[:200]  # a zip whose members and directory are cut off (a crash mid-copy)


@pytest.mark.parametrize("content", [b"", b"not an npz at all", b"PK\x03\x04garbage", truncated_npz()],
                         ids=["empty", "text", "zip-magic", "truncated"])
def test_a_damaged_array_entry_is_a_miss(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "pca-train-abc.npz"
    path.write_bytes(content)
    assert read_arrays(path, NAMES) is None
    write_arrays(path, entry_arrays())  # the recomputed entry replaces it
    assert read_arrays(path, NAMES) is not None


def test_an_entry_without_one_of_the_arrays_is_a_miss(tmp_path: Path) -> None:
    path = tmp_path / "pca-train-abc.npz"
    write_arrays(path, {"train_u": np.zeros((3, 2))})
    assert read_arrays(path, NAMES) is None


def test_an_absent_entry_is_a_miss(tmp_path: Path) -> None:
    assert read_arrays(tmp_path / "pca-train-none.npz", NAMES) is None
