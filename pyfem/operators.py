"""Assembled operators of the explicit model: lumped mass, stiffness, boundary faces.

dolfinx assembles everything once, before the time loop:
- mass: row-sum lumped mass, M_i = int rho phi_i dx (one value per node);
- stiffness: K_ij = int sigma(phi_j) : eps(phi_i) dx of linear isotropic
  elasticity, no boundary conditions, as a scipy BSR matrix with 3x3 blocks;
- faces: per truncation face (where the model is cut, docs/boundaries.md; never a
  cavity or lining surface), the lumped facet integrals of 1, n, rho c_p, rho c_s
  and G that the viscoelastic boundary and the seismic input forces need.

Numbering (docs/ARCHITECTURE.md): a node is a dof block of
VectorFunctionSpace(mesh, ("Lagrange", order)); dof = 3 * node + component.
The assembly helpers live in `pyfem.assembly` (re-exported here: assemble_nodal_vector,
lumped_mass, elastic_stiffness), the material constants in `pyfem.material`.
"""
from __future__ import annotations

import dataclasses
import typing

import numpy as np
import scipy.sparse
import ufl
from dolfinx import fem, geometry
from dolfinx import mesh as dolfinx_mesh
from mpi4py import MPI

from pyfem.assembly import (SPACE_DIMENSION, assemble_nodal_vector, elastic_stiffness, facet_measure,
                            hrz_lumped_vector, lumped_mass, uses_diagonal_scaling)
from pyfem.geometry import BOX_FACES
from pyfem.interfaces import interface_pairs
from pyfem.material import Material
from pyfem.mesh import create_mesh_with_interfaces
from pyfem.errors import SceneError

SUPPORTED_ORDERS = (1, 2)


@dataclasses.dataclass
class BoundaryFace:
    """Lumped facet data of one truncation face (per face node).

    Attributes:
        name: physical surface name (box: xmin, xmax, ymin, ymax, zmin, zmax), or for the
            exterior facets on a bounding-box plane of a mesh without such names, the plane's.
        nodes: (k,) int32 nodes of the face with nonzero lumped area.
        area: (k,) lumped area int phi_i ds (m^2).
        normal: (k, 3) unit outward normal, normalised int phi_i n ds (-).
        rho_cp: (k,) int phi_i rho c_p ds (kg/s), P-wave dashpot per unit velocity.
        rho_cs: (k,) int phi_i rho c_s ds (kg/s), S-wave dashpot per unit velocity.
        shear_modulus: (k,) int phi_i G ds (N/m = Pa m^2).
        plane_distance: (k,) |n . (x_node - centre)| (m), R of the viscoelastic boundary.
        kind: boundary type of the face: "viscoelastic", "viscous", "fixed", "roller", "free".
        source: how the face was found: "boundary.faces", "named surface" or "bounding-box plane".
        n_facets: number of mesh facets of the face.
    """

    name: str
    nodes: np.ndarray
    area: np.ndarray
    normal: np.ndarray
    rho_cp: np.ndarray
    rho_cs: np.ndarray
    shear_modulus: np.ndarray
    plane_distance: np.ndarray
    kind: str = "viscoelastic"
    source: str = "named surface"
    n_facets: int = 0
    traction_area: np.ndarray | None = None

    @property
    def load_area(self) -> np.ndarray:
        """(k,) the weights int phi_i ds of the input's traction term A sigma_ff n (m^2): the row sums,
        the consistent load of a uniform traction. Equal to `area` except on quadratic triangles,
        where `area` is HRZ-lumped (positive springs and dashpots at every node) and the row sums
        vanish at the vertices: a traction lumped with HRZ weights is not the load the interior's
        stiffness balances, and the boundary nodes then followed the free field to first order only."""
        return self.area if self.traction_area is None else self.traction_area

    @property
    def total_area(self) -> float:
        """Area of the face (m^2): the sum of its lumped nodal areas."""
        return float(np.sum(self.area))


@dataclasses.dataclass
class Model:
    """Mesh, function space and assembled operators of a scene (docs/ARCHITECTURE.md "Model").

    Attributes:
        mesh: dolfinx mesh.
        V: vector Lagrange space of order 1 (Q1) or 2 (Q2), block size 3.
        cell_tags, facet_tags: dolfinx MeshTags of regions and named surfaces.
        regions: region name -> cell tag.
        boundaries: boundary/interface name -> facet tag.
        node_coords: (n_nodes, 3) node coordinates (m).
        mass: (n_nodes,) row-sum lumped mass (kg), > 0.
        stiffness: (3 n_nodes, 3 n_nodes) BSR matrix with (3, 3) blocks (N/m).
        faces: one BoundaryFace per truncation face (docs/boundaries.md).
        free_surfaces: named exterior surfaces that are not truncation faces (cavity walls,
            lining faces: traction-free), and "(unnamed)" for other exterior facets, with their
            facet counts.
        interface_tags: split interface name -> (facet tag of side i, of side j); empty without contact.
        pairs: contact node pairs of the split interfaces (pyfem.interfaces.NodePairs), or None.
    """

    mesh: dolfinx_mesh.Mesh
    V: fem.FunctionSpace
    cell_tags: typing.Any
    facet_tags: typing.Any
    regions: dict[str, int]
    boundaries: dict[str, int]
    node_coords: np.ndarray
    mass: np.ndarray
    stiffness: scipy.sparse.bsr_matrix
    faces: list[BoundaryFace]
    free_surfaces: dict = dataclasses.field(default_factory=dict)
    interface_tags: dict = dataclasses.field(default_factory=dict)
    pairs: typing.Any = None
    _materials: typing.Optional["CellMaterials"] = dataclasses.field(default=None, repr=False, compare=False)
    _cell_locator: typing.Any = dataclasses.field(default=None, repr=False, compare=False)

    @property
    def n_cells(self) -> int:
        """Number of cells owned by this rank."""
        return self.mesh.topology.index_map(self.mesh.topology.dim).size_local

    @property
    def n_nodes(self) -> int:
        """Number of nodes (owned + ghost) on this rank."""
        return self.node_coords.shape[0]

    @property
    def n_dofs(self) -> int:
        """Number of dofs (owned + ghost) on this rank: 3 per node."""
        return SPACE_DIMENSION * self.n_nodes

    @property
    def order(self) -> int:
        """Polynomial order of the Lagrange space (1: Q1, 2: Q2)."""
        return self.V.ufl_element().degree()

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) corners of the axis-aligned bounding box of the whole mesh (m)."""
        comm = self.mesh.comm
        # (allreduce's MIN and MAX compare whole objects, not numpy arrays elementwise)
        lo = np.min(comm.allgather(self.node_coords.min(axis=0)), axis=0)
        hi = np.max(comm.allgather(self.node_coords.max(axis=0)), axis=0)
        return lo, hi

    def volume_of_region(self, name: str) -> float:
        """Volume of region `name` (m^3), summed over all ranks."""
        if name not in self.regions:
            raise ValueError(f"region {name!r}: unknown; regions are {sorted(self.regions)}")
        indicator = self._materials.indicator
        region_cells = self.cell_tags.indices[self.cell_tags.values == self.regions[name]]
        indicator.x.array[:] = 0.0
        indicator.x.array[self._materials.dof_of_cell[region_cells]] = 1.0
        local = fem.assemble_scalar(fem.form(indicator * ufl.dx(domain=self.mesh)))
        return self.mesh.comm.allreduce(local, op=MPI.SUM)

    def point_weights(self, points: np.ndarray, cells: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Interpolation weights of nodal values at arbitrary points.

        value(p_j) = sum_k weights[j, k] * value[nodes[j, k]] for any nodal
        field (exact for every field in the space: trilinear for Q1,
        triquadratic for Q2).

        Args:
            points: (m, 3) coordinates (m); each inside the mesh on this rank.
            cells: the local cell containing each point; None: the first found.

        Returns:
            nodes (m, k) int32 and weights (m, k) float64, k = 8 (Q1) or 27 (Q2).
        """
        cells, reference_points = self._located_points(points, cells)
        basix_element = self.V.element.basix_element
        nodes = np.empty((len(cells), basix_element.dim), dtype=np.int32)
        weights = np.empty((len(cells), basix_element.dim), dtype=np.float64)
        for j, (cell, reference_point) in enumerate(zip(cells, reference_points)):
            weights[j] = basix_element.tabulate(0, reference_point)[0, 0, :, 0]
            nodes[j] = self.V.dofmap.cell_dofs(cell)
        return nodes, weights

    def point_gradient_weights(self, points: np.ndarray,
                               cells: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Weights of the gradient of a nodal field at arbitrary points.

        For a vector field with nodal values U (n_nodes, 3),
        dU_i/dx_l (p_j) = sum_k U[nodes[j, k], i] * gradients[j, k, l]: the basis
        gradients at the point's reference coordinates X, mapped by the inverse
        Jacobian, dphi/dx = dphi/dX J^-1 with J = dx/dX = sum_a x_a (x) dphi_a/dX.
        J is built from the space's own nodes, which is exact for any geometry the
        space contains (the Q1 geometry of these meshes, for Q1 and Q2).
        The gradient is that of the containing cell (the strain of a Q1/Q2 field
        jumps across cell faces; a point on a face gets one of its cells).

        Args:
            points: (m, 3) coordinates (m); each inside the mesh on this rank.
            cells: the local cell containing each point; None: the first found.

        Returns:
            nodes (m, k) int32, gradients (m, k, 3) float64 (1/m), and cells (m,) int32
            (the local cell each point was evaluated in), k = 8 (Q1) or 27 (Q2).
        """
        cells, reference_points = self._located_points(points, cells)
        basix_element = self.V.element.basix_element
        n_basis = basix_element.dim
        nodes = np.empty((len(cells), n_basis), dtype=np.int32)
        gradients = np.empty((len(cells), n_basis, SPACE_DIMENSION), dtype=np.float64)
        for j, (cell, reference_point) in enumerate(zip(cells, reference_points)):
            # tabulate(1, X): [value, d/dX, d/dY, d/dZ] x points x basis x value size.
            reference_gradients = basix_element.tabulate(1, reference_point)[1:, 0, :, 0].T   # (k, 3)
            cell_nodes = self.V.dofmap.cell_dofs(cell)
            jacobian = self.node_coords[cell_nodes].T @ reference_gradients                  # (3, 3) dx/dX
            gradients[j] = reference_gradients @ np.linalg.inv(jacobian)
            nodes[j] = cell_nodes
        return nodes, gradients, cells

    def region_of_cells(self, cells: np.ndarray) -> list[str]:
        """Region name (scene material) of each local cell; ValueError for an untagged cell."""
        tag_of_region = {tag: name for name, tag in self.regions.items()}
        order = np.argsort(self.cell_tags.indices)
        sorted_cells = self.cell_tags.indices[order]
        names = []
        for cell in np.atleast_1d(cells):
            position = np.searchsorted(sorted_cells, cell)
            if position >= len(sorted_cells) or sorted_cells[position] != cell:
                raise ValueError(f"cell {cell} has no region tag")
            names.append(tag_of_region[int(self.cell_tags.values[order[position]])])
        return names

    def _located_points(self, points, cells: np.ndarray | None = None) -> tuple[np.ndarray, list]:
        """Containing cell (`cells` when given) and reference coordinates (each (1, 3)) of (m, 3) points (m)."""
        points = np.asarray(points, dtype=np.float64)
        if points.ndim == 1:
            points = points.reshape(1, -1)
        if points.ndim != 2 or points.shape[1] != SPACE_DIMENSION:
            raise ValueError(f"points: shape {points.shape} given; expected (m, 3) coordinates (m)")
        cells = self._containing_cells(points) if cells is None else np.asarray(cells, dtype=np.int32)
        geometry_dofmap = self.mesh.geometry.dofmap
        geometry_x = self.mesh.geometry.x
        coordinate_map = self.mesh.geometry.cmap
        reference_points = [coordinate_map.pull_back(point.reshape(1, -1), geometry_x[geometry_dofmap.links(cell)])
                            for point, cell in zip(points, cells)]
        return cells, reference_points

    def cells_holding(self, points: np.ndarray) -> list:
        """Per point, every local cell containing it (several on a face, an edge or a node)."""
        if self._cell_locator is None:
            self._cell_locator = geometry.BoundingBoxTree(self.mesh, self.mesh.topology.dim)
        candidates = geometry.compute_collisions(self._cell_locator, points)
        colliding = geometry.compute_colliding_cells(self.mesh, candidates, points)
        return [np.asarray(colliding.links(j), dtype=np.int32) for j in range(points.shape[0])]

    def cell_centroids(self, cells: np.ndarray) -> np.ndarray:
        """(c, 3) mean of each local cell's geometry nodes (m)."""
        dofmap = self.mesh.geometry.dofmap
        n_geometry = dofmap.offsets[1] - dofmap.offsets[0]
        return self.mesh.geometry.x[dofmap.array.reshape(-1, n_geometry)[np.asarray(cells, dtype=np.int32)]].mean(axis=1)

    def preferred_cell(self, cells: np.ndarray) -> tuple[int, np.ndarray]:
        """Of cells holding one point, the one whose centroid is lowest in x, then y, then z, and that
        centroid: a point on a face, an edge or a node between cells gets the same cell whatever the
        numbering or the rank count (its stress and strain are that cell's)."""
        centroids = self.cell_centroids(cells)
        k = int(np.lexsort((centroids[:, 2], centroids[:, 1], centroids[:, 0]))[0])
        return int(cells[k]), centroids[k]

    def _containing_cells(self, points: np.ndarray) -> np.ndarray:
        """One cell containing each point (`preferred_cell`), or ValueError naming the first point outside."""
        cells = np.empty(points.shape[0], dtype=np.int32)
        for j, (point, found) in enumerate(zip(points, self.cells_holding(points))):
            if len(found) == 0:
                raise PointOutsideMesh(j, point, *self.bounds)
            cells[j] = self.preferred_cell(found)[0]
        return cells


class PointOutsideMesh(ValueError):
    """A point in no cell of the mesh: `index` in the points asked for, and where it lies."""

    def __init__(self, index: int, point, lo, hi):
        self.index, self.point = index, [float(x) for x in point]
        inside_box = bool(np.all(np.asarray(point) >= lo) and np.all(np.asarray(point) <= hi))
        self.where = ("inside the mesh's bounding box but in no cell (a cavity, an excavated region or a gap)"
                      if inside_box else "outside the mesh's bounding box")
        box = f"[{', '.join(f'{x:.6g}' for x in lo)}] to [{', '.join(f'{x:.6g}' for x in hi)}] m"
        super().__init__(f"point {self.point} is {self.where}; bounding box {box}")


@dataclasses.dataclass
class CellMaterials:
    """Cellwise-constant (DG0) material fields built from scene["materials"].

    Attributes:
        rho: density (kg/m^3).
        lame_lambda: Lame's first parameter (Pa).
        shear_modulus: G = mu (Pa).
        rho_cp: rho * c_p, P-wave impedance (kg/(m^2 s)).
        rho_cs: rho * c_s, S-wave impedance (kg/(m^2 s)).
        indicator: scratch DG0 function for region integrals.
        dof_of_cell: (n_cells_local,) DG0 dof of each local cell.
    """

    rho: fem.Function
    lame_lambda: fem.Function
    shear_modulus: fem.Function
    rho_cp: fem.Function
    rho_cs: fem.Function
    indicator: fem.Function
    dof_of_cell: np.ndarray


def lame_parameters(E: float, nu: float) -> tuple[float, float]:
    """Lame's lambda and the shear modulus G (Pa) from Young's modulus E (Pa) and Poisson's ratio nu (-).

    `pyfem.material.Material(...).lame`, kept for the callers that have no density at hand (the
    density does not enter; ValueError for E or nu out of range).
    """
    return Material(E=E, nu=nu, rho=1.0).lame


def build_model(scene: typing.Mapping, comm: MPI.Comm = MPI.COMM_WORLD) -> Model:
    """Mesh the scene and assemble its lumped mass, stiffness and boundary faces.

    Args:
        scene: validated scene; uses [mesh], [materials] and [boundary].centre.
        comm: MPI communicator (the stiffness is assembled for one rank only).

    Returns:
        The Model of docs/ARCHITECTURE.md.
    """
    order = scene["mesh"].get("order", 1)
    if order not in SUPPORTED_ORDERS:
        raise ValueError(f"mesh.order = {order!r}: allowed are {SUPPORTED_ORDERS} (Q1, Q2)")
    if comm.size > 1:
        # getValuesCSR returns owned rows with global columns; the kernel's
        # owned + ghost numbering needs a local renumbering not written yet.
        raise NotImplementedError(f"build_model: runs on one MPI rank for now (communicator has {comm.size})")
    mesh, cell_tags, facet_tags, regions, boundaries, interface_tags = create_mesh_with_interfaces(scene, comm)
    V = fem.VectorFunctionSpace(mesh, ("Lagrange", order))
    materials = _cell_materials(mesh, cell_tags, regions, scene["materials"])
    quadrature = {"quadrature_degree": 2 * order}

    node_coords = V.tabulate_dof_coordinates().astype(np.float64, copy=True)
    mass = lumped_mass(V, materials.rho, quadrature)
    stiffness = elastic_stiffness(V, materials.lame_lambda, materials.shear_modulus, quadrature)

    centre = scene.get("boundary", {}).get("centre")
    if centre is None:
        centre = 0.5 * (node_coords.min(axis=0) + node_coords.max(axis=0))
    centre = np.asarray(centre, dtype=np.float64)
    if centre.shape != (SPACE_DIMENSION,):
        raise ValueError(f"boundary.centre = {scene['boundary']['centre']!r}: expected [x, y, z] (m)")
    truncation, free_surfaces = truncation_faces(scene, mesh, facet_tags, boundaries, interface_tags)
    kinds = face_kinds(scene, truncation)
    faces = [
        boundary_face(name, V, facets, materials, node_coords, centre, quadrature, kind=kinds[name], source=source)
        for name, (facets, source) in truncation.items()
    ]
    pairs = None
    if interface_tags:
        pairs = interface_pairs(V, facet_tags, interface_tags, mass, node_coords, quadrature)
    return Model(mesh=mesh, V=V, cell_tags=cell_tags, facet_tags=facet_tags, regions=regions,
                 boundaries=boundaries, node_coords=node_coords, mass=mass, stiffness=stiffness,
                 faces=faces, free_surfaces=free_surfaces, interface_tags=interface_tags, pairs=pairs,
                 _materials=materials)


def _cell_materials(mesh, cell_tags, regions: dict[str, int], material_tables: typing.Mapping) -> CellMaterials:
    """DG0 fields of rho, lambda, G, rho c_p, rho c_s, constant per region."""
    Q = fem.FunctionSpace(mesh, ("DG", 0))
    n_cells = mesh.topology.index_map(mesh.topology.dim).size_local + mesh.topology.index_map(
        mesh.topology.dim).num_ghosts
    dof_of_cell = Q.dofmap.list.array.reshape(n_cells, -1)[:, 0].astype(np.int32)
    fields = {name: fem.Function(Q, name=name) for name in ("rho", "lame_lambda", "shear_modulus", "rho_cp", "rho_cs")}
    covered = np.zeros(n_cells, dtype=bool)
    for region, tag in regions.items():
        material = Material.from_scene(region, material_tables[region])
        rho_cp, rho_cs = material.impedances
        values = {"rho": material.rho, "lame_lambda": material.lame_lambda,
                  "shear_modulus": material.shear_modulus, "rho_cp": rho_cp, "rho_cs": rho_cs}
        region_cells = cell_tags.indices[cell_tags.values == tag]
        covered[region_cells] = True
        for key, value in values.items():
            fields[key].x.array[dof_of_cell[region_cells]] = value
    if not np.all(covered):
        raise ValueError(f"mesh: {np.count_nonzero(~covered)} cells belong to no region (physical volume)")
    return CellMaterials(indicator=fem.Function(Q), dof_of_cell=dof_of_cell, **fields)


def boundary_face(name: str, V: fem.FunctionSpace, facets: np.ndarray, materials: CellMaterials,
                  node_coords: np.ndarray, centre: np.ndarray, quadrature: dict, kind: str = "viscoelastic",
                  source: str = "named surface") -> BoundaryFace:
    """Lumped facet integrals over the given exterior facets (local facet indices).

    DG0 material fields on an exterior facet take the value of the one cell
    adjacent to it.
    """
    mesh = V.mesh
    facets = np.unique(np.asarray(facets, dtype=np.int32))
    ds = facet_measure(mesh, facets, quadrature)
    test = ufl.TestFunction(V)
    outward_normal = ufl.FacetNormal(mesh)
    if uses_diagonal_scaling(V):
        # Quadratic triangles: row sums vanish at the vertices; HRZ keeps every node's share > 0.
        one = fem.Constant(mesh, 1.0)
        scalars = np.column_stack([hrz_lumped_vector(c, V, ds) for c in (one, materials.rho_cp, materials.rho_cs)])
        shear = hrz_lumped_vector(materials.shear_modulus, V, ds)
        normal_integral = np.column_stack([hrz_lumped_vector(outward_normal[c], V, ds, scale=False)
                                           for c in range(3)])
        row_sums = assemble_nodal_vector(ufl.inner(ufl.as_vector((1.0, 0.0, 0.0)), test) * ds, V)[:, 0]
    else:
        # One vector form carries three scalar integrals: component 0: 1, 1: rho c_p, 2: rho c_s.
        scalars = assemble_nodal_vector(
            ufl.inner(ufl.as_vector((1.0, materials.rho_cp, materials.rho_cs)), test) * ds, V)
        shear = assemble_nodal_vector(materials.shear_modulus * test[0] * ds, V)[:, 0]
        normal_integral = assemble_nodal_vector(ufl.inner(outward_normal, test) * ds, V)

    area = scalars[:, 0]
    nodes = np.flatnonzero(area != 0.0).astype(np.int32)
    traction_area = row_sums[nodes].copy() if uses_diagonal_scaling(V) else None
    if np.any(area[nodes] < 0.0):
        raise ValueError(f"boundary {name!r}: negative lumped facet area at nodes {nodes[area[nodes] < 0.0][:5]}")
    normal = normal_integral[nodes]
    normal_length = np.linalg.norm(normal, axis=1)
    if np.any(normal_length <= 0.0):
        raise ValueError(f"boundary {name!r}: a node has no defined normal (facets cancel out)")
    normal = normal / normal_length[:, None]
    plane_distance = np.abs(np.einsum("ij,ij->i", normal, node_coords[nodes] - centre))
    return BoundaryFace(name=name, nodes=nodes, area=area[nodes].copy(), normal=normal,
                        rho_cp=scalars[nodes, 1].copy(), rho_cs=scalars[nodes, 2].copy(),
                        shear_modulus=shear[nodes].copy(), plane_distance=plane_distance, kind=kind,
                        source=source, n_facets=int(len(facets)), traction_area=traction_area)


# Relative distance (of the model's extent) within which a facet lies on a bounding-box plane.
_PLANE_TOLERANCE = 1.0e-8


def truncation_faces(scene: typing.Mapping, mesh, facet_tags, boundaries: dict[str, int],
                     interface_tags: typing.Mapping = ()) -> tuple[dict, dict]:
    """The faces where the model is cut (they carry the artificial boundary and the input).

    In order: the physical surfaces named in `boundary.faces`; else the surfaces named xmin,
    xmax, ymin, ymax, zmin, zmax that the mesh has; else the exterior facets lying on the
    planes of the mesh's bounding box (one face per plane, named after it). Every other
    exterior surface (a cavity, a lining face, a tunnel wall) is traction-free.

    Returns:
        (faces, free_surfaces): faces maps a face name to (local facet indices int32, source);
        free_surfaces maps the named exterior surfaces that are not truncation faces, and
        "(unnamed)" for the remaining exterior facets, to their facet counts.

    On a mesh distributed over ranks (mesh.comm) every rank gets the same face names (a face
    may have no facets on a rank), the bounding box is the whole mesh's and the counts are summed,
    so that the faces' collective assembly meets on every rank.

    Raises:
        SceneError: boundary.faces names an unknown surface, or one that is not on the exterior.
    """
    comm = mesh.comm
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    exterior = dolfinx_mesh.exterior_facet_indices(mesh.topology)
    split = {tag for tags in dict(interface_tags).values() for tag in tags}
    surfaces = {name: facet_tags.indices[facet_tags.values == tag] for name, tag in boundaries.items()
                if name not in dict(interface_tags) and tag not in split}
    given = (scene.get("boundary") or {}).get("faces")
    faces: dict[str, tuple[np.ndarray, str]] = {}
    if given:
        for index, name in enumerate(given):
            if name not in surfaces:
                raise SceneError(f"boundary.faces.{index}", name,
                                 "names of physical surfaces of the mesh: " + ", ".join(sorted(surfaces)))
            facets = surfaces[name]
            outside = comm.allreduce(bool(np.all(np.isin(facets, exterior))), op=MPI.LAND)
            if comm.allreduce(len(facets)) == 0 or not outside:
                raise SceneError(f"boundary.faces.{index}", name,
                                 "surfaces on the exterior of the mesh (this one has facets inside it)")
            faces[name] = (facets.astype(np.int32), "boundary.faces")
    elif any(name in surfaces for name in BOX_FACES):
        for name in BOX_FACES:
            if name in surfaces:
                facets = surfaces[name]
                faces[name] = (facets[np.isin(facets, exterior)].astype(np.int32), "named surface")
    else:
        x = mesh.geometry.x
        lo = np.min(comm.allgather(x.min(axis=0) if len(x) else np.full(3, np.inf)), axis=0)
        hi = np.max(comm.allgather(x.max(axis=0) if len(x) else np.full(3, -np.inf)), axis=0)
        tolerance = _PLANE_TOLERANCE * float(np.max(hi - lo))
        for name in BOX_FACES:
            axis = "xyz".index(name[0])
            value = lo[axis] if name.endswith("min") else hi[axis]
            facets = dolfinx_mesh.locate_entities_boundary(
                mesh, tdim - 1, lambda points, a=axis, v=value: np.abs(points[a] - v) <= tolerance)
            facets = facets[np.isin(facets, exterior)]
            if comm.allreduce(len(facets)):
                faces[name] = (facets.astype(np.int32), "bounding-box plane")
    on_faces = np.concatenate([f for f, _ in faces.values()]) if faces else np.zeros(0, dtype=np.int32)
    free_surfaces = {}
    named = np.zeros(0, dtype=np.int32)
    for name, facets in surfaces.items():
        outside = facets[np.isin(facets, exterior)]
        named = np.concatenate([named, outside])
        count = comm.allreduce(len(outside))
        if name not in faces and count and not comm.allreduce(bool(np.all(np.isin(outside, on_faces))), op=MPI.LAND):
            free_surfaces[name] = int(count)
    interface_facets = np.concatenate([facet_tags.indices[facet_tags.values == tag] for tag in split]) \
        if split else np.zeros(0, dtype=np.int32)
    unnamed = comm.allreduce(len(np.setdiff1d(exterior, np.concatenate([named, on_faces, interface_facets]))))
    if unnamed:
        free_surfaces["(unnamed)"] = int(unnamed)
    return faces, free_surfaces


def face_kinds(scene: typing.Mapping, faces: typing.Mapping) -> dict[str, str]:
    """Boundary type of each truncation face: `boundary.face.NAME.type`, else `boundary.type`.

    Raises:
        SceneError: a `boundary.face.NAME` table names no truncation face.
    """
    boundary = scene.get("boundary") or {}
    per_face = boundary.get("face") or {}
    for name, table in per_face.items():
        if name not in faces:
            raise SceneError(f"boundary.face.{name}", table,
                             "tables named after truncation faces: " + (", ".join(faces) or "none found")
                             + " (set boundary.faces to choose them)")
    default = boundary.get("type", "viscoelastic")
    return {name: (per_face.get(name) or {}).get("type") or default for name in faces}


def face_report(model) -> list[dict]:
    """Per truncation face: name, type, nodes, facets, area (m^2), whether it carries input, how
    it was found; for `check`, run.json and the README."""
    from pyfem.seismic.forces import INPUT_TYPES

    return [{"name": face.name, "type": face.kind, "nodes": int(len(face.nodes)), "facets": face.n_facets,
             "area": face.total_area, "input": face.kind in INPUT_TYPES, "source": face.source}
            for face in model.faces]


NO_REGION = -1
"""The region id of a cell without a region tag."""


def cell_regions(model) -> np.ndarray:
    """(n_cells,) int32 region id of every cell of the dofmap: its cell tag (`Model.regions` maps
    the names to these ids), NO_REGION where a cell has none."""
    n_cells = len(model.V.dofmap.list.array) // model.V.dofmap.dof_layout.num_dofs
    regions = np.full(n_cells, NO_REGION, dtype=np.int32)
    indices = np.asarray(model.cell_tags.indices)
    keep = indices < n_cells
    regions[indices[keep]] = np.asarray(model.cell_tags.values)[keep]
    return regions
