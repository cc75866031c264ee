// Two rock masses separated by a dipping fault (an x-z section extruded along y), meshed to
// tetrahedra of 3 m; the fault is the physical surface "fault". With gmsh 4.8 this mesh holds one
// node that no tetrahedron uses (tests/test_tetrahedra_contact.py: pyfem drops it before dolfinx
// sees the split mesh). From a new-user trial of contact on the distributed model (2026-11-29).
Point(1) = {0, 0, 0, 3.0};
Point(2) = {80, 0, 0, 3.0};
Point(3) = {80, 0, 50, 3.0};
Point(4) = {0, 0, 50, 3.0};
Point(5) = {0, 0, 20, 3.0};
Point(6) = {80, 0, 32, 3.0};
Line(1) = {1, 2};
Line(2) = {2, 6};
Line(3) = {6, 5};
Line(4) = {5, 1};
Line(5) = {6, 3};
Line(6) = {3, 4};
Line(7) = {4, 5};
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Curve Loop(2) = {-3, 5, 6, 7};
Plane Surface(2) = {2};
out[] = Extrude {0, 8, 0} { Surface{1, 2}; };
Physical Volume("limestone") = {out[1]};
Physical Volume("claystone") = {out[7]};
Physical Surface("fault") = {out[4]};
Mesh.MshFileVersion = 4.1;
Mesh.CharacteristicLengthMax = 3.0;
