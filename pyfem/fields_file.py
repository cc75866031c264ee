"""Reads a run's fields.xdmf (+ .h5) back: the points, the cells and every field time.

Two layouts are read. dolfinx's XDMFFile (the distributed model's, on any number of ranks, the one
writer of the one model): the mesh once, the cell tags once as the grid "region", then one temporal
collection per field; a second-order model's cells as 27-node hexahedra or 10-node tetrahedra
(pyfem.quadratic_fields: every node of the function space, VTK's node order); the tensors as
3 x 3 cell data. meshio's (the serial RunWriter's): every field of a time in one grid,
a Q2 cell split into 8 hexahedra so that every node is a point, the tensors as XDMF Tensor6.

`read_fields` gives both the same way: tensors as 6 components xx, xy, xz, yy, yz, zz (Tensor6),
scalars as (n,), and the cell field "region" (int32 region ids, run.json "regions") at every time.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

# dolfinx's 3 x 3 tensor (row by row) -> Tensor6 xx, xy, xz, yy, yz, zz.
TENSOR6 = [0, 1, 2, 4, 5, 8]


@dataclass
class Fields:
    """points (n, 3) m; cells (c, k) indices into points (VTK hexahedra or tetrahedra, linear or, in
    dolfinx's layout of a second-order model, quadratic: corners first); steps: one
    (t, point_data, cell_data) per field time, in time order, each data a {name: array}."""

    points: np.ndarray
    cells: np.ndarray
    steps: list

    @property
    def times(self) -> list[float]:
        return [t for t, _, _ in self.steps]


def _hdf(item: ET.Element, data) -> np.ndarray:
    """The array an XDMF DataItem "file.h5:/path" names."""
    return np.asarray(data[item.text.strip().split(":", 1)[1]])


def read_fields(path) -> Fields:
    """Reads fields.xdmf at `path` (dolfinx's layout or meshio's, see the module's docstring)."""
    path = Path(path)
    root = ET.parse(path).getroot()
    domain = root.find("Domain")
    if domain.find("Grid[@Name='TimeSeries_meshio']") is not None:
        return _read_meshio(path)
    return _read_dolfinx(path, domain)


def _read_meshio(path: Path) -> Fields:
    import meshio

    with meshio.xdmf.TimeSeriesReader(str(path)) as reader:
        points, cells = reader.read_points_cells()
        steps = []
        for k in range(reader.num_steps):
            t, point_data, cell_data = reader.read_data(k)
            steps.append((float(t), dict(point_data), {name: values[0] for name, values in cell_data.items()}))
    return Fields(np.asarray(points), np.asarray(cells[0].data), steps)


def _read_dolfinx(path: Path, domain: ET.Element) -> Fields:
    import h5py

    with h5py.File(path.with_suffix(".h5"), "r") as data:
        mesh = domain.find("Grid[@Name='mesh']")
        cells = _hdf(mesh.find("Topology/DataItem"), data).astype(np.int64)
        points = _hdf(mesh.find("Geometry/DataItem"), data)
        region = None
        tags = domain.find("Grid[@Name='region']")
        if tags is not None:  # the cell tags: their own cell list, mapped onto the mesh's by vertices
            tagged = _hdf(tags.find("Topology/DataItem"), data).astype(np.int64)
            values = _hdf(tags.find("Attribute/DataItem"), data).reshape(-1)
            row = {tuple(c): k for k, c in enumerate(np.sort(cells, axis=1).tolist())}
            region = np.zeros(len(cells), dtype=np.int32)
            region[[row[tuple(c)] for c in np.sort(tagged, axis=1).tolist()]] = values
        by_time: dict[float, tuple[dict, dict]] = {}
        for collection in domain.findall("Grid[@GridType='Collection']"):
            for grid in collection.findall("Grid"):
                t = float(grid.find("Time").get("Value"))
                point_data, cell_data = by_time.setdefault(t, ({}, {}))
                for attribute in grid.findall("Attribute"):
                    values = _hdf(attribute.find("DataItem"), data)
                    values = values.reshape(len(values), -1)
                    if values.shape[1] == 9:
                        values = values[:, TENSOR6]
                    elif values.shape[1] == 1:
                        values = values[:, 0]
                    target = cell_data if attribute.get("Center") == "Cell" else point_data
                    target[attribute.get("Name")] = values
    steps = []
    for t in sorted(by_time):
        point_data, cell_data = by_time[t]
        if region is not None:
            cell_data["region"] = region
        steps.append((t, point_data, cell_data))
    return Fields(points, cells, steps)

