MODULE PickPath
    CONST robtarget Target_10:=[[0,0,200],[0,0,1,0],[-1,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_20:=[[0,0,0],[0,0,1,0],[-1,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_30:=[[600,0,0],[0,0,1,0],[-1,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_40:=[[600,800,0],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_50:=[[0,800,0],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_60:=[[300,400,-20],[0,0.0871557,0.9961947,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_70:=[[300,400,250],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_80:=[[-200,-150,500],[0.258819,0,0.9659258,0],[-1,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    PERS tooldata tGripper:=[TRUE,[[0,0,250],[1,0,0,0]],[22,[0,0,110],[1,0,0,0],0.6,0.6,0.4]];
    TASK PERS wobjdata wobjTable:=[FALSE,TRUE,"",[[1150,-400,300],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
    !***********************************************************
    !
    ! Module:  PickPath
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
        MoveJ Target_10,v2000,z100,tGripper\WObj:=wobjTable;
        MoveL Target_20,v500,fine,tGripper\WObj:=wobjTable;
        MoveL Target_30,v500,z5,tGripper\WObj:=wobjTable;
        MoveL Target_40,v500,z5,tGripper\WObj:=wobjTable;
        MoveL Target_50,v500,z5,tGripper\WObj:=wobjTable;
        MoveL Target_20,v500,z5,tGripper\WObj:=wobjTable;
        MoveJ Target_70,v1000,z50,tGripper\WObj:=wobjTable;
        MoveL Target_60,v100,fine,tGripper\WObj:=wobjTable;
        MoveL Target_70,v1000,z20,tGripper\WObj:=wobjTable;
        MoveJ Target_80,v2000,z200,tGripper\WObj:=wobjTable;
    ENDPROC
ENDMODULE
