"""File formats: car-test bags (read, write, typestore), bench CSV."""
