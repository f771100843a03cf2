// Thigh-like cross-section for the CalculiX comparison test (crates/femu-mech/tests/calculix.rs).
// Units: mm. Skin: ellipse 70 x 60 mm; fat band down to an inner ellipse 62 x 52 mm; muscle
// split at y = 0 into an anterior (y > 0) and a posterior (y < 0) region; femur: circular hole
// of radius 14 mm centred at (5, -4). All-quad mesh: Frontal-Delaunay triangles recombined by
// the full-quad Blossom algorithm (no triangle is left). Mesh.Algorithm = 8 (Frontal-Delaunay
// for quads) crashes gmsh 4.8.4 on this geometry, and plain Blossom leaves 12 triangles.
//
// Regenerate (the .msh is committed; CI does not run gmsh):
//   gmsh thigh_ccx.geo -2 -o thigh_ccx.msh
// (gmsh 4.8.4 was used.)

lc = 4.5;
a = 70; b = 60;     // skin semi-axes
ai = 62; bi = 52;   // fat / muscle interface semi-axes
xc = 5; yc = -4; r = 14;  // femur
dx = Sqrt(r*r - yc*yc);   // femur circle meets y = 0 at xc -/+ dx

Point(1) = {0, 0, 0, lc};
// skin
Point(2) = {a, 0, 0, lc};  Point(3) = {0, b, 0, lc};
Point(4) = {-a, 0, 0, lc}; Point(5) = {0, -b, 0, lc};
// fat / muscle interface
Point(6) = {ai, 0, 0, lc};  Point(7) = {0, bi, 0, lc};
Point(8) = {-ai, 0, 0, lc}; Point(9) = {0, -bi, 0, lc};
// femur
Point(10) = {xc, yc, 0, lc};
Point(11) = {xc + dx, 0, 0, lc};
Point(12) = {xc - dx, 0, 0, lc};
Point(13) = {xc, yc - r, 0, lc};

Ellipse(1) = {2, 1, 2, 3}; Ellipse(2) = {3, 1, 4, 4};
Ellipse(3) = {4, 1, 4, 5}; Ellipse(4) = {5, 1, 2, 2};
Ellipse(5) = {6, 1, 6, 7}; Ellipse(6) = {7, 1, 8, 8};
Ellipse(7) = {8, 1, 8, 9}; Ellipse(8) = {9, 1, 6, 6};
Circle(9) = {11, 10, 12};   // upper femur arc (through y > 0)
Circle(10) = {12, 10, 13};
Circle(11) = {13, 10, 11};
Line(12) = {11, 6};
Line(13) = {8, 12};

Curve Loop(1) = {1, 2, 3, 4};
Curve Loop(2) = {5, 6, 7, 8};
Plane Surface(1) = {1, 2};                      // fat
Curve Loop(3) = {5, 6, 13, -9, 12};
Plane Surface(2) = {3};                          // anterior muscle
Curve Loop(4) = {7, 8, -12, -11, -10, -13};
Plane Surface(3) = {4};                          // posterior muscle

Physical Surface("FAT") = {1};
Physical Surface("ANTERIOR") = {2};
Physical Surface("POSTERIOR") = {3};
Physical Curve("SKIN") = {1, 2, 3, 4};
Physical Curve("FEMUR") = {9, 10, 11};

Mesh.Algorithm = 6;
Mesh.RecombinationAlgorithm = 3;
Mesh.RecombineAll = 1;
Mesh.MshFileVersion = 4.1;
Mesh.Binary = 0;
