MODULE m
PROC main()
MoveL nowhere, v100, z1, tool0;
ENDPROC
ENDMODULE
