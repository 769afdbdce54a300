"""Colour grading domain: photos <-> RGB histograms, colour maps, LUTs and presets."""
