G1 X1 F100
(unclosed comment
