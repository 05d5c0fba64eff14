%
O1004 (GA-REFERENCE)
(mtwin sample mimicking the GA milling-optimisation reference: a 6 mm two-flute carbide flat end mill)
(in aluminium 6061 on the default 11 kW / 8,000 rpm machine; slots and side cuts of several depths)
(with the conservative feeds and speed of a first program. Optimise with:)
(mtwin optimize samples/ga_reference.nc -o opt.nc --method ga --feed-range 100,500 --spindle-range 1000,8000 --force-limit 60)
(T1 D=6. CR=0. - ZMIN=-3. - FLAT END MILL, 2 FLUTES, CARBIDE)
(MTWIN STOCK 0,0,-10,30,50,0)
G21 G90 G17 G40 G49 G80 G94
T1 M6
G54 G0 X-4. Y5. S8000 M3
G43 H1 Z5. M8
(slot 1 mm deep)
G0 Z-1.
G1 X34. F500.
G0 Z5.
(slot 2 mm deep)
G0 X-4. Y15.
G0 Z-2.
G1 X34. F500.
G0 Z5.
(slot 3 mm deep, half at 1 mm: a step in the load)
G0 X-4. Y25.
G0 Z-1.
G1 X12. F500.
G1 Z-3. F100.
G1 X29.9 F405.
G1 X34. F500.
G0 Z5.
(side cut of the last slot's wall, 1.5 mm wide, 3 mm deep)
G0 X34. Y29.5
G0 Z-3.
G1 X12. F500.
G0 Z5.
(shallow facing pass 0.5 mm, full width)
G0 X-4. Y40.
G0 Z-0.5
G1 X34. F500.
G0 Z5. M9
M5
G91 G28 Z0.
M30
%
