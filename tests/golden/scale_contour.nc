%
O1002 (CONTOUR)
(mtwin sample: outside contour of a 50 x 40 mm plate, R8 corners, a circular boss cut-out, 5 mm deep, helical entry, Al 6061, metric)
(T2 D=6. CR=0. - FLAT END MILL, 2 FLUTES, CARBIDE)
(MTWIN STOCK -10,-10,-12,70,60,0)
G21 G90 G17 G94 G64 P0.01
T2 M6
G0 G54 X-8. Y-8. S9000 M3
G43 H2 Z5. M8
G1 Z-5. F250.
G1 X-3. Y8. F1500.
G1 Y32.
G2 X8. Y43. R11.
G1 X42.
G2 X53. Y32. R11.
G1 Y8.
G2 X42. Y-3. R11.
G1 X8.
G2 X-3. Y8. R11.
G0 Z5.
(boss cut-out: helical ramp then full circle)
G0 X31. Y20.
G1 Z0.5 F375.
G3 X31. Y20. I-6. J0. Z-1.5 F750.
G3 X31. Y20. I-6. J0. Z-3.5
G3 X31. Y20. I-6. J0. Z-5.
G3 X31. Y20. I-6. J0.
G1 X25. Y20.
G0 Z5. M9
M5
G91 G28 Z0.
G90
M30
%
