"""Photos graded end to end (``apply``): read, grade, write, the report and its sheets."""
