"""What users run: fixed-vs-float analysis, word-length proposals, CSV input and output, the
Quartus project writer."""
