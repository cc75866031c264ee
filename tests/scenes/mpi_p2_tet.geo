// tests/scenes/mpi_p2_tet.toml's mesh: two layers (60 x 10 x 40 m, rock below 20 m, a softer layer
// above) meshed to tetrahedra by gmsh (size 5 m), one physical volume per layer.
SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 60, 10, 20};
Box(2) = {0, 0, 20, 60, 10, 20};
BooleanFragments{ Volume{1, 2}; Delete; }{}
Physical Volume("lower") = {1};
Physical Volume("upper") = {2};
Mesh.MeshSizeMax = 5;
Mesh.MeshSizeMin = 5;
