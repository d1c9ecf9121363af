"""The files subtrace reads and writes: text decoding (text), the one atomic writer
(atomic), OBJ cages (obj, obj_scan) and their render limits (limits), TOML scenes (scene),
EXR / PNG images (exr), line CSVs (lines_csv)."""
