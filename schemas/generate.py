"""Regenerate plugins/facedynSchemas/resources/ from schemas/schema.usda.

    python schemas/generate.py            # write the generated files
    python schemas/generate.py --validate # exit 1 if the committed files drift from schema.usda

usdGenSchema leaves build-system placeholders in plugInfo.json (a C++ build fills them in);
a codeless schema shipped as plain files needs them resolved, which this script does after
running `python -m pxr.Usd.usdGenSchema` (needs jinja2). The face role tokens come from the
one role table, facedyn.performance.BUILTIN_ROLES, filled into schema.usda's "@FACE_ROLES@"
before generation.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from facedyn.performance import BUILTIN_ROLES

HERE = Path(__file__).resolve().parent
SCHEMA = HERE / "schema.usda"
RESOURCES = HERE.parent / "plugins" / "facedynSchemas" / "resources"
GENERATED = ("plugInfo.json", "generatedSchema.usda")
PLACEHOLDERS = {
    '"@PLUG_INFO_LIBRARY_PATH@"': '""',
    '"@PLUG_INFO_RESOURCE_PATH@"': '"resources"',
    '"@PLUG_INFO_ROOT@"': '".."',
}


FACE_ROLES_PLACEHOLDER = '"@FACE_ROLES@"'


def filled_schema() -> str:
    """schema.usda with the face role tokens of the role table filled in."""
    tokens = ", ".join(f'"{role.name}"' for role in BUILTIN_ROLES if role.face_role)
    return SCHEMA.read_text().replace(FACE_ROLES_PLACEHOLDER, tokens)


def generate(out_dir: Path) -> None:
    """Run usdGenSchema into out_dir and resolve plugInfo.json's placeholders."""
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / SCHEMA.name
        source.write_text(filled_schema())
        subprocess.run(
            [sys.executable, "-m", "pxr.Usd.usdGenSchema", str(source), str(out_dir)],
            check=True,
            cwd=HERE,
            stdout=subprocess.DEVNULL,
        )
    plug_info = out_dir / "plugInfo.json"
    text = plug_info.read_text()
    for placeholder, value in PLACEHOLDERS.items():
        text = text.replace(placeholder, value)
    plug_info.write_text(text)


def drifted_files(reference_dir: Path) -> list[str]:
    """Names of the generated files whose committed copy differs from a fresh generation."""
    with tempfile.TemporaryDirectory() as tmp:
        fresh = Path(tmp)
        generate(fresh)
        return [
            name
            for name in GENERATED
            if not (reference_dir / name).is_file()
            or (reference_dir / name).read_text() != (fresh / name).read_text()
        ]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--validate", action="store_true", help="check instead of writing")
    args = parser.parse_args()
    if args.validate:
        drift = drifted_files(RESOURCES)
        if drift:
            print(f"generated schema files out of date: {', '.join(drift)}; run python schemas/generate.py")
            return 1
        print("generated schema files match schemas/schema.usda")
        return 0
    generate(RESOURCES)
    print(f"wrote {', '.join(GENERATED)} to {RESOURCES}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
