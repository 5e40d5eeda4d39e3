"""What users run: fixed-vs-float analysis, word-length proposals, the Quartus project writer."""
