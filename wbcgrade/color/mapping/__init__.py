"""A colour map applied to pixels (remap, regrain) and written as a 3-D LUT."""
