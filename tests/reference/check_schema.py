"""Validates pipeline files against schemas/pipeline.schema.json with the `jsonschema` package.

Usage: check_schema.py SCHEMA PIPELINE... ; exits non-zero on the first invalid file.
A deliberately broken copy of each file (an unknown key) must be rejected, so the check can fail.
"""
import copy
import json
import sys

import jsonschema
import yaml


def main(schema_path, *pipelines):
    schema = json.load(open(schema_path))
    jsonschema.Draft7Validator.check_schema(schema)
    validator = jsonschema.Draft7Validator(schema)
    for path in pipelines:
        doc = yaml.safe_load(open(path))
        errors = sorted(validator.iter_errors(doc), key=str)
        if errors:
            sys.exit(f"{path}: {errors[0].message} at {list(errors[0].absolute_path)}")
        broken = copy.deepcopy(doc)
        first_stage = next(iter(broken["stages"].values()))
        first_stage["parms"] = {}
        if validator.is_valid(broken):
            sys.exit(f"{path}: the schema accepted an unknown stage key")
        print(f"{path}: valid")


if __name__ == "__main__":
    main(*sys.argv[1:])
