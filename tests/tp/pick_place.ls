/PROG  PICK_PLACE
/ATTR
OWNER		= MNEDITOR;
COMMENT		= "bin to fixture";
PROG_SIZE	= 1846;
CREATE		= DATE 25-03-11  TIME 08:14:52;
MODIFIED	= DATE 25-03-12  TIME 16:02:10;
FILE_NAME	= ;
VERSION		= 0;
LINE_COUNT	= 17;
MEMORY_SIZE	= 2290;
PROTECT		= READ_WRITE;
TCD:  STACK_SIZE	= 0,
      TASK_PRIORITY	= 50,
      TIME_SLICE	= 0,
      BUSY_LAMP_OFF	= 0,
      ABORT_REQUEST	= 0,
      PAUSE_REQUEST	= 0;
DEFAULT_GROUP	= 1,*,*,*,*;
CONTROL_CODE	= 00000000 00000000;
/APPL
/MN
   1:  UFRAME_NUM=1 ;
   2:  UTOOL_NUM=2 ;
   3:J P[1:home] 50% FINE    ;
   4:  ! approach the bin ;
   5:J P[2:above bin] 100% CNT100    ;
   6:L P[3:pick] 500mm/sec FINE    ;
   7:  RO[1]=ON ;
   8:  WAIT   0.30(sec) ;
   9:L P[2:above bin] 1000mm/sec CNT50    ;
  10:  UFRAME_NUM=3 ;
  11:J PR[5:fixture app] 100% CNT100    ;
  12:L P[4:place] 300mm/sec FINE    ;
  13:  RO[1]=OFF ;
  14:L P[5] 800mm/sec CNT30 Offset,PR[7]    ;
  15:J P[1:home] 100% FINE    ;
  16:  PR[6]=LPOS    ;
  17:  CALL DONE_SIGNAL    ;
/POS
P[1:"home"]{
   GP1:
	UF : 1, UT : 2,
	J1=     0.000 deg,	J2=     0.000 deg,	J3=     0.000 deg,
	J4=     0.000 deg,	J5=   -90.000 deg,	J6=     0.000 deg
};
P[2:"above bin"]{
   GP1:
	UF : 1, UT : 2,		CONFIG : 'N U T, 0, 0, 0',
	X =   420.500  mm,	Y =  -135.250  mm,	Z =   180.000  mm,
	W =   180.000 deg,	P =     0.000 deg,	R =   -90.000 deg
};
P[3:"pick"]{
   GP1:
	UF : 1, UT : 2,		CONFIG : 'N U T, 0, 0, 0',
	X =   420.500  mm,	Y =  -135.250  mm,	Z =    62.750  mm,
	W =   180.000 deg,	P =     0.000 deg,	R =   -90.000 deg
};
P[4:"place"]{
   GP1:
	UF : 3, UT : 2,		CONFIG : 'N U T, 0, 0, 0',
	X =    35.000  mm,	Y =    48.000  mm,	Z =    12.500  mm,
	W =  -179.500 deg,	P =     1.250 deg,	R =     0.000 deg
};
P[5]{
   GP1:
	UF : 3, UT : 2,		CONFIG : 'N U T, 0, 0, 0',
	X =    35.000  mm,	Y =    48.000  mm,	Z =   110.000  mm,
	W =  -179.500 deg,	P =     1.250 deg,	R =     0.000 deg
};
/END
