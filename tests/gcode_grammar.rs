//! Integration tests: every example of grammar/gcode.md parses as documented.
