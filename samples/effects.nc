%
O1005 (EFFECTS DEMO - AFM R-1000, T1 10 MM 3-FLUTE END MILL, G54)
(Exercises every effect: milling force - static deflection,)
(spindle and drive heat - thermal drift, tooth passing near)
(the 55 Hz Y mode at S1100 - vibration warning.)
G90 G17 G21 G54
T1 M6
G43 H1 G0 Z50.
G0 X0. Y0.
S6000 M3
(POSTPROC MILLING DEPTH=2 WIDTH=3)
G0 Z2.
G1 Z-2. F300.
G1 X200. F900.
G1 Y40.
G1 X0.
G2 X0. Y80. I0. J20.
G1 X200.
(POSTPROC MILLING DEPTH=1 WIDTH=10)
G1 Y120. F600.
G0 Z50.
(Slow spindle: 1100 rpm x 3 flutes = 55 Hz, the Y mode)
S1100 M3
G0 X50. Y150.
G1 Z-1. F200.
G1 X150. F165.
G0 Z50.
(Drilling with the same tool as a plunge)
G81 X100. Y200. Z-5. R2. F300.
G80
G4 P2000
M5
M30
%
