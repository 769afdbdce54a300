"""The grade path: map builders, the frozen Grade, saved grades."""
