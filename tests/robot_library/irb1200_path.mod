MODULE Module1
    CONST robtarget Target_10:=[[0,0,60],[0,0,1,0],[-1,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_20:=[[0,0,0],[0,0,1,0],[-1,-1,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_30:=[[150,0,0],[0,0,1,0],[-1,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_40:=[[150,220,0],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_50:=[[0,220,0],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_60:=[[75,110,-5],[0.0436194,0,0.9990482,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_70:=[[75,110,60],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget Target_80:=[[-40,-30,120],[0.1305262,0,0.9914449,0],[-1,0,-1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    PERS tooldata MyTool:=[TRUE,[[0,0,120],[1,0,0,0]],[0.8,[0,0,45],[1,0,0,0],0,0,0]];
    TASK PERS wobjdata Workobject_1:=[FALSE,TRUE,"",[[330,-110,180],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
    !***********************************************************
    !
    ! Module:  Module1
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
        MoveJ Target_10,v1000,z50,MyTool\WObj:=Workobject_1;
        MoveL Target_20,v200,fine,MyTool\WObj:=Workobject_1;
        MoveL Target_30,v200,z1,MyTool\WObj:=Workobject_1;
        MoveL Target_40,v200,z1,MyTool\WObj:=Workobject_1;
        MoveL Target_50,v200,z1,MyTool\WObj:=Workobject_1;
        MoveL Target_20,v200,z1,MyTool\WObj:=Workobject_1;
        MoveJ Target_70,v500,z20,MyTool\WObj:=Workobject_1;
        MoveL Target_60,v50,fine,MyTool\WObj:=Workobject_1;
        MoveL Target_70,v500,z10,MyTool\WObj:=Workobject_1;
        MoveJ Target_80,v1000,z100,MyTool\WObj:=Workobject_1;
    ENDPROC
ENDMODULE
