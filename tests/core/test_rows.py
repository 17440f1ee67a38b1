"""GrowingRows against a list of rows kept beside it."""

import numpy as np

from gpr3d.core.rows import GrowingRows


def test_rows_appended_in_chunks_read_back_as_appended():
    rng = np.random.default_rng(1)
    rows, ref = GrowingRows(2, 3), []
    for _ in range(60):  # chunks of 0..100 rows (the first array holds 64: it grows several times)
        k = int(rng.integers(0, 101))
        chunk = rng.normal(size=(k, 2, 3))
        rows.append(chunk)
        ref.extend(chunk)
        assert len(rows) == rows.n == len(ref)
    np.testing.assert_array_equal(rows[:], np.array(ref))
    np.testing.assert_array_equal(rows[-1], ref[-1])
    assert rows[:].shape == (len(ref), 2, 3) and len(rows._a) < 4 * len(ref)
    one = GrowingRows(3)
    one.append([1.0, 2.0, 3.0])  # (a single row)
    one.append(np.zeros((0, 3)))  # (none)
    assert one[:].tolist() == [[1.0, 2.0, 3.0]]


def test_scalar_rows_keep_their_dtype():
    flags, times = GrowingRows(dtype=bool), GrowingRows()
    flags.append([True, False])
    flags.append(True)
    times.append(0.5)
    times.append([1, 2])
    assert flags[:].dtype == bool and flags[:].tolist() == [True, False, True]
    assert times[:].dtype == np.float64 and times[:].tolist() == [0.5, 1.0, 2.0] and times[-1] == 2.0
    assert len(GrowingRows(4)) == 0 and GrowingRows(4)[:].shape == (0, 4)
