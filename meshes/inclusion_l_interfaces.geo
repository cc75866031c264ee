// An inclusion (x 40-80 m, z 0-20 m) in a host rock, in contact on its top (z = 20 m) and its side
// (x = 40 m): two interfaces that meet in an L along the edge (40, y, 20), whose nodes are in two
// pairs (a pair group). Hexahedra; from a new-user trial (2026-11-29).
Point(1) = {0, 0, 0}; Point(2) = {40, 0, 0}; Point(3) = {80, 0, 0};
Point(4) = {0, 0, 20}; Point(5) = {40, 0, 20}; Point(6) = {80, 0, 20};
Point(7) = {0, 0, 50}; Point(8) = {40, 0, 50}; Point(9) = {80, 0, 50};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 6}; Line(4) = {6, 5}; Line(5) = {5, 4}; Line(6) = {4, 1};
Line(7) = {2, 5}; Line(8) = {5, 8}; Line(9) = {8, 7}; Line(10) = {7, 4}; Line(11) = {6, 9}; Line(12) = {9, 8};
Curve Loop(1) = {1, 7, 5, 6}; Plane Surface(1) = {1};
Curve Loop(2) = {2, 3, 4, -7}; Plane Surface(2) = {2};
Curve Loop(3) = {-5, 8, 9, 10}; Plane Surface(3) = {3};
Curve Loop(4) = {-4, 11, 12, -8}; Plane Surface(4) = {4};
Transfinite Curve{1, 2, 4, 5, 9, 12} = 11;
Transfinite Curve{3, 6, 7} = 6;
Transfinite Curve{8, 10, 11} = 8;
Transfinite Surface{1, 2, 3, 4};
Recombine Surface{1, 2, 3, 4};
out[] = Extrude {0, 8, 0} { Surface{1, 2, 3, 4}; Layers{2}; Recombine; };
Physical Volume("host") = {out[1], out[13], out[19]};
Physical Volume("inclusion") = {out[7]};
Physical Surface("top") = {out[10]};
Physical Surface("side") = {out[3]};
