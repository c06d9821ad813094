MODULE CalibData
  ! Palletizing cell, IRB 1600: gripper, conveyor work object and the
  ! taught pick and place positions (conveyor frame).
  PERS tooldata tGripper := [TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,60],[1,0,0,0],0,0,0]];
  TASK PERS wobjdata wTable := [FALSE,TRUE,"",[[400,-300,200],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST robtarget pPick := [[500,150,300],[0.1828804,0.0723086,0.9537141,0.2274985],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pPlace := [[500,450,300],[0.1828804,-0.0723086,0.9537141,-0.2274985],[0,-1,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  LOCAL CONST robtarget pService := [[0,0,0],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
ENDMODULE
