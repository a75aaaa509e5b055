"""Non-USD formats (BVH, OBJ sequences, Live Link Face CSV), resampling, and safe file access."""
from facedyn.lazy_exports import lazy_exports

_PUBLIC = {
    "head_trajectory": "bvh",
    "InputError": "errors",
    "check_not_special": "files", "open_regular": "files", "read_lines": "files", "read_text": "files",
    "sha256_of_file": "files", "write_atomically": "files",
    "read_livelink_csv": "livelink",
    "ObjFrames": "obj",
    "CubicResampler": "resample", "resample_curves": "resample",
}

__all__, __getattr__ = lazy_exports(__name__, _PUBLIC)
