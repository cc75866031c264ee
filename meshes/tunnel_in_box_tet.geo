// A circular tunnel in a slab of rock, meshed with tetrahedra by gmsh: the example of a user's
// own .geo for the `file` mesh builder (docs/tetrahedra.md; tests/test_tetrahedra.py runs it).
//
// The tunnel (radius 5 m, axis along y through x = z = 60 m) crosses the box
// [0, 120] x [0, 2] x [0, 120] m. Element size 0.4 m at the wall, growing by 0.12 m per metre
// of distance to 8 m. One physical volume, "rock"; no surface is named, so pyfem takes the
// exterior facets on the bounding-box planes as the truncation faces and the wall is free.
//
//   [mesh]
//   builder = "file"
//   file = "meshes/tunnel_in_box_tet.geo"   # gmsh meshes it when the run starts
//   order = 1                               # or 2: quadratic tetrahedra, HRZ-lumped mass
SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 120, 2, 120};
Cylinder(2) = {60, 0, 60, 0, 2, 0, 5};
BooleanDifference(3) = { Volume{1}; Delete; }{ Volume{2}; Delete; };
Physical Volume("rock") = {3};

Field[1] = MathEval;
Field[1].F = "min(8, 0.4 + 0.12 * (sqrt((x - 60)^2 + (z - 60)^2) - 5))";
Background Field = 1;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeFromCurvature = 0;
