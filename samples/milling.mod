%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%

MODULE Milling
  ! IRB 1600-10/1.45 milling cell (machine file samples/irb1600-milling.yaml):
  ! the side wall of a 160 x 110 mm pocket, 10 mm deep, in an aluminium
  ! plate clamped on the table in front of the robot, with a 10 mm two-flute
  ! end mill. A roughing lap at 5 mm depth, 2 mm wide (the machine file's
  ! defaults), then a finishing lap at full depth, 0.5 mm wide, at 20000 rpm.
  ! Plate frame wPart: origin at the front-left corner of the plate top,
  ! 600 mm in front of the base, 200 mm to the right, 350 mm up. Tool centre
  ! path 5 mm inside the wall; entry through a pre-drilled hole at the
  ! first corner.

  ! Spindle: TCP 182.5 mm along the flange z axis, 2.4 kg, centre of gravity
  ! 85 mm out from the flange.
  PERS tooldata tMill := [TRUE,[[0,0,182.5],[1,0,0,0]],[2.4,[0,0,85],[1,0,0,0],0.012,0.012,0.004]];
  PERS wobjdata wPart := [FALSE,TRUE,"",[[600,-200,350],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];

  ! Feed 20 mm/s (1200 mm/min): 0.033 mm per tooth at 18000 rpm.
  CONST speeddata vMill := [20,30,5000,1000];
  CONST speeddata vPlunge := [5,20,5000,1000];

  CONST jointtarget jHome := [[0,-10,20,0,80,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pClear := [[750,0,650],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];

  ! Corners of the tool centre path on the plate top (wPart frame), tool
  ! pointing down.
  CONST robtarget corner{4} := [
    [[100,250,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[250,250,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[250,350,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[100,350,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];

  PROC main()
    MoveAbsJ jHome\NoEOffs, v1000, fine, tMill;
    MoveJ pClear, v1000, z50, tMill;
    SetDO doSpindle, 1;
    WaitTime 2;
    ! roughing lap: the machine file's depth and width
    MoveJ Offs(corner{1},0,0,30), v500, z10, tMill\WObj:=wPart;
    MoveL Offs(corner{1},0,0,-5), vPlunge, fine, tMill\WObj:=wPart;
    MoveL Offs(corner{2},0,0,-5), vMill, z1, tMill\WObj:=wPart;
    MoveL Offs(corner{3},0,0,-5), vMill, z1, tMill\WObj:=wPart;
    MoveL Offs(corner{4},0,0,-5), vMill, z1, tMill\WObj:=wPart;
    MoveL Offs(corner{1},0,0,-5), vMill, fine, tMill\WObj:=wPart;
    ! finishing lap at full depth
    ! POSTPROC MILLING DEPTH=10 WIDTH=0.5 RPM=20000
    MoveL Offs(corner{1},0,0,-10), vPlunge, fine, tMill\WObj:=wPart;
    MoveL Offs(corner{2},0,0,-10), vMill, z1, tMill\WObj:=wPart;
    MoveL Offs(corner{3},0,0,-10), vMill, z1, tMill\WObj:=wPart;
    MoveL Offs(corner{4},0,0,-10), vMill, z1, tMill\WObj:=wPart;
    MoveL Offs(corner{1},0,0,-10), vMill, fine, tMill\WObj:=wPart;
    MoveL Offs(corner{1},0,0,30), v100, z10, tMill\WObj:=wPart;
    SetDO doSpindle, 0;
    MoveJ pClear, v1000, z50, tMill;
    MoveAbsJ jHome\NoEOffs, v1000, fine, tMill;
  ENDPROC
ENDMODULE
