"""Board constraints: the pin table, the .sdc and the .qsf template."""
