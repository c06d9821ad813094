/PROG  WELD_SEAM_4
/ATTR
OWNER		= MNEDITOR;
COMMENT		= "fillet seam";
PROG_SIZE	= 2410;
CREATE		= DATE 25-02-03  TIME 11:40:02;
MODIFIED	= DATE 25-02-03  TIME 11:58:30;
FILE_NAME	= ;
VERSION		= 0;
LINE_COUNT	= 13;
MEMORY_SIZE	= 2862;
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

ARC Welding Equipment : 1,*,*,*,*;
/MN
   1:  UFRAME_NUM=2 ;
   2:  UTOOL_NUM=1 ;
   3:J P[1] 30% FINE    ;
   4:L P[2] 200mm/sec FINE    ;
   5:  Arc Start[1] ;
   6:C P[3]    
    :  P[4] 12mm/sec CNT100    ;
   7:C P[5]    
    :  P[6] 12mm/sec CNT100    ;
   8:C P[7]    
    :  P[8] 12mm/sec CNT100    ;
   9:C P[9]    
    :  P[10] 12mm/sec CNT100    ;
  10:L P[11] 12mm/sec FINE    ;
  11:  Arc End[1] ;
  12:L P[12] 300mm/sec CNT100    ;
  13:J P[1] 50% FINE    ;
/POS
P[1]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   950.000  mm,	Y =  -220.000  mm,	Z =   480.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
P[2]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   950.000  mm,	Y =  -220.000  mm,	Z =   402.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
P[3]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   970.000  mm,	Y =  -200.000  mm,	Z =   402.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
P[4]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   990.000  mm,	Y =  -220.000  mm,	Z =   402.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
P[5]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =  1010.000  mm,	Y =  -200.000  mm,	Z =   402.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
P[6]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =  1030.000  mm,	Y =  -220.000  mm,	Z =   402.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
P[7]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =  1050.000  mm,	Y =  -200.000  mm,	Z =   402.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
P[8]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =  1070.000  mm,	Y =  -220.000  mm,	Z =   402.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
P[9]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =  1090.000  mm,	Y =  -200.000  mm,	Z =   402.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
P[10]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =  1110.000  mm,	Y =  -220.000  mm,	Z =   402.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
P[11]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =  1170.000  mm,	Y =  -220.000  mm,	Z =   402.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
P[12]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =  1170.000  mm,	Y =  -220.000  mm,	Z =   480.000  mm,
	W =  -145.000 deg,	P =    -8.500 deg,	R =    92.000 deg
};
/END
