%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%

MODULE Drilling
  ! IRB 1600-10/1.45 drilling cell: twelve 6.8 mm holes (M8 tapping size) in
  ! an aluminium plate clamped on the table in front of the robot.
  ! Plate frame wPlate: origin at the front-left corner of the plate top,
  ! 600 mm in front of the base, 200 mm to the right, 350 mm up; the holes
  ! lie 700-850 mm in front of the base, y -150..150 mm, z 350 mm.

  ! Spindle drill: TCP 182.5 mm along the flange z axis, 2.4 kg, centre of
  ! gravity 85 mm out from the flange.
  PERS tooldata tDrill := [TRUE,[[0,0,182.5],[1,0,0,0]],[2.4,[0,0,85],[1,0,0,0],0.012,0.012,0.004]];
  PERS wobjdata wPlate := [FALSE,TRUE,"",[[600,-200,350],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];

  ! Feeds: drilling 4 mm/s (thrust: machine file process_force), retract 100 mm/s.
  CONST speeddata vDrill := [4,20,5000,1000];
  CONST speeddata vRetract := [100,200,5000,1000];
  CONST zonedata zApproach := [FALSE,5,8,8,0.8,8,0.8];
  CONST num nHoles := 12;
  CONST num depth := 12;   ! drilling depth below the plate top, mm
  VAR bool spindleOn := FALSE;

  CONST jointtarget jHome := [[0,-10,20,0,80,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pClear := [[750,0,650],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];

  ! Hole centres on the plate top (wPlate frame), tool pointing down.
  CONST robtarget holes{12} := [
    [[100,50,0],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[100,150,0],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[100,250,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[100,350,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[175,50,0],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[175,150,0],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[175,250,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[175,350,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[250,50,0],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[250,150,0],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[250,250,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[250,350,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];

  PROC main()
    MoveAbsJ jHome\NoEOffs, v1000, fine, tDrill;
    MoveJ pClear, v1000, z50, tDrill;
    SetDO doSpindle, 1;
    spindleOn := TRUE;
    WaitTime 2;
    ! hole 1
    MoveJ Offs(holes{1},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{1},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{1},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{1},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    ! hole 2
    MoveJ Offs(holes{2},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{2},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{2},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{2},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    ! hole 3
    MoveJ Offs(holes{3},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{3},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{3},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{3},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    ! hole 4
    MoveJ Offs(holes{4},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{4},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{4},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{4},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    ! hole 5
    MoveJ Offs(holes{5},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{5},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{5},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{5},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    ! hole 6
    MoveJ Offs(holes{6},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{6},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{6},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{6},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    ! hole 7
    MoveJ Offs(holes{7},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{7},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{7},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{7},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    ! hole 8
    MoveJ Offs(holes{8},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{8},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{8},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{8},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    ! hole 9
    MoveJ Offs(holes{9},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{9},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{9},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{9},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    ! hole 10
    MoveJ Offs(holes{10},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{10},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{10},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{10},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    ! hole 11
    MoveJ Offs(holes{11},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{11},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{11},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{11},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    ! hole 12
    MoveJ Offs(holes{12},0,0,40), v500, zApproach, tDrill\WObj:=wPlate;
    MoveL Offs(holes{12},0,0,2), v50, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{12},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    MoveL Offs(holes{12},0,0,40), vRetract, z10, tDrill\WObj:=wPlate;
    SetDO doSpindle, 0;
    spindleOn := FALSE;
    MoveJ pClear, v1000, z50, tDrill;
    MoveAbsJ jHome\NoEOffs, v1000, fine, tDrill;
  ENDPROC
ENDMODULE
