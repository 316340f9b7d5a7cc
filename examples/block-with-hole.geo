// The lower block of the built-in block-with-hole scene in gmsh's .geo language: physical curves name
// the parts (one "face", the contact face); examples/block-with-hole-geo.toml uses it.
Point(1) = {10, 0, 0};
Point(2) = {10, -20, 0};
Point(3) = {-10, -20, 0};
Point(4) = {-10, 0, 0};
Line(1) = {4, 1};
Line(2) = {1, 2};
Line(3) = {2, 3};
Line(4) = {3, 4};
Point(5) = {0, -10, 0};
Point(6) = {0.5, -10, 0};
Point(7) = {0, -9.5, 0};
Point(8) = {-0.5, -10, 0};
Point(9) = {0, -10.5, 0};
Circle(5) = {6, 5, 7};
Circle(6) = {7, 5, 8};
Circle(7) = {8, 5, 9};
Circle(8) = {9, 5, 6};
Physical Curve("face") = {1};
Physical Curve("right") = {2};
Physical Curve("bottom") = {3};
Physical Curve("left") = {4};
Physical Curve("hole") = {5, 6, 7, 8};
