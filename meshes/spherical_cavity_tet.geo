// A 60 m box of rock with a 4 m spherical cavity, tetrahedra graded from 0.5 m at the wall to 7 m
// (17 892 dofs at order 1): a new user's gmsh script (2026-11-29), the small graded model on which
// local stepping was 2x slower than global stepping before the kernel threaded small levels
// (docs/local_stepping.md "When it is on"; workflows/scenes/spherical_cavity_lts.toml).
SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 60, 60, 60};
Sphere(2) = {30, 30, 30, 4};
BooleanDifference(3) = { Volume{1}; Delete; }{ Volume{2}; Delete; };
Physical Volume("rock") = {3};
Field[1] = MathEval;
Field[1].F = "min(7, 0.5 + 0.2 * (sqrt((x - 30)^2 + (y-30)^2 + (z - 30)^2) - 4))";
Background Field = 1;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeFromCurvature = 0;
