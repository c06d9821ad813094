MODULE GoFaPath
    CONST robtarget Target_10:=[[0,0,80],[0,0,1,0],[-1,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_20:=[[0,0,0],[0,0,1,0],[-1,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_30:=[[150,0,0],[0,0,1,0],[-1,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_40:=[[150,200,0],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    PERS tooldata tSuction:=[TRUE,[[0,0,90],[1,0,0,0]],[0.5,[0,0,40],[1,0,0,0],0,0,0]];
    TASK PERS wobjdata wobjConveyor:=[FALSE,TRUE,"",[[400,-100,150],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
    !***********************************************************
    !
    ! Module:  GoFaPath
    !
    ! Description:
    !   <Insert description here>
    !
    ! Author: cell
    !
    ! Version: 1.0
    !
    !***********************************************************
    
    
    !***********************************************************
    !
    ! Procedure main
    !
    !   This is the entry point of your program
    !
    !***********************************************************
    PROC main()
        Path_10;
    ENDPROC
    PROC Path_10()
        MoveJ Target_10,v1000,z50,tSuction\WObj:=wobjConveyor;
        MoveL Target_20,v200,fine,tSuction\WObj:=wobjConveyor;
        MoveL Target_30,v200,z10,tSuction\WObj:=wobjConveyor;
        MoveL Target_40,v200,fine,tSuction\WObj:=wobjConveyor;
    ENDPROC
ENDMODULE
