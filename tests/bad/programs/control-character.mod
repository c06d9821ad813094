MODULE M
  PROC main()
    MoveL p[2J, v100, z1, tool0;
  ENDPROC
ENDMODULE
