"""The XDMF time series of transient snapshots (fem_squeal.util.vtu)."""
from __future__ import annotations

import filecmp

import meshio
import numpy as np

from fem_squeal.util.vtu import _xml_series_writer


def test_fast_xml_series_is_meshios_text_byte_for_byte(tmp_path):
    """The one-``%``-per-array formatting writes exactly what meshio's savetxt writes: float64 over
    the whole exponent range, ±0, a subnormal, ±inf and NaN, float32 values and integer cells."""
    rng = np.random.default_rng(3)
    points = rng.standard_normal((40, 3))
    cells = [("tetra", rng.integers(0, 40, (30, 4)).astype(np.int64))]
    data = [rng.standard_normal((40, 3)) * 10.0 ** rng.integers(-300, 300, (40, 1)),
            np.tile([0.0, -0.0, 5e-324], (40, 1)), np.tile([np.inf, -np.inf, np.nan], (40, 1)),
            rng.standard_normal((40, 3)).astype(np.float32)]
    for name, writer in (("meshio.xdmf", meshio.xdmf.TimeSeriesWriter), ("fast.xdmf", _xml_series_writer(meshio))):
        with writer(tmp_path / name, data_format="XML") as w:
            w.write_points_cells(points, cells)
            for k, u in enumerate(data):
                w.write_data(float(k), point_data={"u": u})
    assert filecmp.cmp(tmp_path / "meshio.xdmf", tmp_path / "fast.xdmf", shallow=False)
    back = meshio.xdmf.TimeSeriesReader(tmp_path / "fast.xdmf")
    back.read_points_cells()
    t, pd, _ = back.read_data(0)
    assert t == 0.0 and np.array_equal(pd["u"], data[0])
