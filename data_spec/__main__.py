"""Command line: ``python3 -m data_spec validate DIR`` and ``python3 -m data_spec scene FILE``."""

from __future__ import annotations

import argparse
import sys

from data_spec.scene import SceneError, load_scene
from data_spec.validate import validate_dataset


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python3 -m data_spec",
        description="Check liver FEM scenes and datasets against the data_spec v1 contract.")
    sub = parser.add_subparsers(dest="command", required=True)
    v = sub.add_parser("validate", help="check every shard of a dataset directory")
    v.add_argument("directory")
    s = sub.add_parser("scene", help="validate a scene TOML file and print it normalised")
    s.add_argument("file")
    args = parser.parse_args(argv)

    if args.command == "validate":
        problems = validate_dataset(args.directory)
        if problems:
            print(f"{args.directory}: {len(problems)} problem(s):", file=sys.stderr)
            for p in problems:
                print(f"  - {p}", file=sys.stderr)
            return 1
        print(f"{args.directory}: valid")
        return 0
    try:
        scene = load_scene(args.file)
    except SceneError as exc:
        print(exc, file=sys.stderr)
        return 1
    print(scene.to_json())
    print(f"# {scene.name}: valid, hash {scene.hash[:16]}, varies: "
          + ", ".join(k for k, v in scene.varies.items() if v), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
