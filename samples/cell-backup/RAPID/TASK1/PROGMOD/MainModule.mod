MODULE MainModule
  ! Stacks parts from the pick position onto the place position, one
  ! layer of 20 mm per cycle.
  VAR robtarget pStack;

  PROC main()
    FOR i FROM 1 TO nLayers DO
      MoveJ Offs(pPick, 0, 0, nLift), v1000, z50, tGripper\WObj:=wTable;
      MoveL pPick, v200, fine, tGripper\WObj:=wTable;
      MoveL Offs(pPick, 0, 0, nLift), v500, z20, tGripper\WObj:=wTable;
      pStack := Offs(pPlace, 0, 0, 20 * (i - 1));
      MoveJ Offs(pStack, 0, 0, nLift), v1000, z50, tGripper\WObj:=wTable;
      MoveL pStack, v200, fine, tGripper\WObj:=wTable;
      MoveL Offs(pStack, 0, 0, nLift), v500, z20, tGripper\WObj:=wTable;
      reg1 := reg1 + 1;
    ENDFOR
    MoveJ pPlace, v1000, fine, tGripper\WObj:=wTable;
  ENDPROC
ENDMODULE
