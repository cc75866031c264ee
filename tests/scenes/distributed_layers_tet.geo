// tests/scenes/distributed_layers_tet.toml's mesh: the three layers of distributed_layers.toml
// (150 x 10 x 60 m, rock below 25 m, a weak layer of 10 m, concrete above) meshed to tetrahedra
// by gmsh (size 5 m), one physical volume per layer, conforming at the layer planes.
SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 150, 10, 25};
Box(2) = {0, 0, 25, 150, 10, 10};
Box(3) = {0, 0, 35, 150, 10, 25};
BooleanFragments{ Volume{1, 2, 3}; Delete; }{}
Physical Volume("lower") = {1};
Physical Volume("weak") = {2};
Physical Volume("concrete") = {3};
Mesh.MeshSizeMax = 5;
Mesh.MeshSizeMin = 5;
