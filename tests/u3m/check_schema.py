#!/usr/bin/python3
"""Validates U3M files against the official schemas with python3-jsonschema and its FormatChecker.

Usage: check_schema.py SCHEMA_DIR FILE...   (SCHEMA_DIR = .../reference/u3m)
Prints one line per error ("FILE: /pointer: message") and exits 1 when any file is invalid.
Debian's jsonschema has no RFC 3339 module, so its FormatChecker skips "date-time"; this script adds
a strict date-time check so that zone-less timestamps fail here as they do for other readers.
"""
import json
import re
import sys

import jsonschema

DATE_TIME = re.compile(
    r"^\d{4}-(0[1-9]|1[0-2])-(0[1-9]|[12]\d|3[01])[Tt]([01]\d|2[0-3]):[0-5]\d:([0-5]\d|60)(\.\d+)?([Zz]|[+-]([01]\d|2[0-3]):[0-5]\d)$")


def main():
    schema_dir, files = sys.argv[1], sys.argv[2:]
    schemas = {
        "1.0": json.load(open(f"{schema_dir}/1.0/u3m_schema_version1.json", encoding="utf-8")),
        "1.1": json.load(open(f"{schema_dir}/1.1/u3m_schema.json", encoding="utf-8")),
    }
    checker = jsonschema.FormatChecker()
    if "date-time" not in checker.checkers:
        checker.checks("date-time")(lambda value: not isinstance(value, str) or bool(DATE_TIME.match(value)))
    failed = False
    for path in files:
        document = json.load(open(path, encoding="utf-8"))
        schema = schemas.get(document.get("schema"))
        if schema is None:
            print(f"{path}: /schema: unknown version {document.get('schema')!r}")
            failed = True
            continue
        validator = jsonschema.Draft7Validator(schema, format_checker=checker)
        for error in validator.iter_errors(document):
            pointer = "/" + "/".join(str(p) for p in error.absolute_path)
            print(f"{path}: {pointer}: {error.message[:300]}")
            failed = True
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
