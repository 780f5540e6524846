"""The XDMF time series of transient snapshots and the VTU field data (fem_squeal.util.vtu)."""
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


def test_field_data_is_inserted_and_the_rest_copied_byte_for_byte(tmp_path):
    """add_vtu_field_data streams the file (it was read and rewritten as text: three copies of a 2.6 GB
    mode file in memory at 1.32M DOFs): the bytes before and after the inserted <FieldData> are the
    file's own, meshio reads the arrays back, no temporary file is left, and a file with no
    <UnstructuredGrid> is refused by name."""
    import pytest

    from fem_squeal.util.vtu import add_vtu_field_data

    rng = np.random.default_rng(0)
    path = tmp_path / "m.vtu"
    meshio.write(path, meshio.Mesh(rng.random((70000, 3)), [("tetra", rng.integers(0, 70000, (30000, 4)))],
                                   point_data={"u": rng.random((70000, 3))}), file_format="vtu", compression=None)
    before = path.read_bytes()
    add_vtu_field_data(path, {"freq_hz": [1.5, 2250.0], "n": [3]})
    after = path.read_bytes()
    i = before.index(b">", before.index(b"<UnstructuredGrid")) + 1
    inserted = after[i:len(after) - (len(before) - i)]
    assert after[:i] == before[:i] and after.endswith(before[i:]) and inserted.startswith(b"\n<FieldData>")
    data = meshio.read(path).field_data
    assert list(data["freq_hz"]) == [1.5, 2250.0] and list(data["n"]) == [3]
    assert [p.name for p in tmp_path.iterdir()] == ["m.vtu"]
    bad = tmp_path / "bad.vtu"
    bad.write_text("<VTKFile></VTKFile>")
    with pytest.raises(ValueError, match="bad.vtu: no <UnstructuredGrid>"):
        add_vtu_field_data(bad, {"x": [1.0]})
    assert bad.read_text() == "<VTKFile></VTKFile>"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.vtu", "m.vtu"]
