"""Files: photos (OpenImageIO), raw camera files, the disk cache, preset names."""
