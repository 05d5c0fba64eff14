%
O1005 (FINISH-WALL)
(mtwin sample: a roughing slot, a light side pass and a 0.2 mm finishing wall pass, Al 6061)
(T1 D=6. CR=0. - FLAT END MILL, 2 FLUTES, CARBIDE)
(MTWIN STOCK 0,-10,-6,60,10,0)
G21 G90 G17 G94
T1 M6
S8000 M3
(ROUGH SLOT)
G0 X-5. Y0. Z5.
G0 Z-2.
G1 X65. F300.
G0 Z5.
(SIDE PASS)
G0 X-5. Y1.
G0 Z-2.
G1 X65. F300.
G0 Z5.
(FINISH WALL PASS)
G0 X-5. Y1.2
G0 Z-2.
G1 X65. F300.
G0 Z5.
M5
M30
%
