MODULE m
CONST robtarget p := [[1,2,1e300],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
PROC main()
MoveL p, v100, z1, tool0;
ENDPROC
ENDMODULE
