"""A small JSON Schema (draft 2020-12 subset) validator for the docs' schemas, so the tests need no
extra package.

Supported keywords: ``type`` (a name or a list: object, array, string, number, integer, boolean,
null), ``properties``, ``required``, ``additionalProperties`` (bool or schema), ``items``,
``minItems``, ``maxItems``, ``enum``, ``const``, ``minimum``, ``maximum``, ``exclusiveMinimum``,
``pattern`` (a string matched anywhere, ``re.search``, as the standard says; the schemas' patterns use the
syntax Python and ECMA 262 share), ``anyOf``, ``allOf``, ``$ref`` to ``#/$defs/NAME``. Annotations (``title``, ``description``,
``$schema``, ``$id``, ``examples``, ``$comment``) are ignored. Any other keyword is an error, so a
schema cannot silently rely on something this validator does not check.
"""
from __future__ import annotations

import re

ANNOTATIONS = {"title", "description", "$schema", "$id", "examples", "$comment", "$defs", "default"}
KEYWORDS = {"type", "properties", "required", "additionalProperties", "items", "minItems", "maxItems", "enum",
            "const", "minimum", "maximum", "exclusiveMinimum", "pattern", "anyOf", "allOf", "$ref"} | ANNOTATIONS


def _is_type(x, t: str) -> bool:
    if t == "object":
        return isinstance(x, dict)
    if t == "array":
        return isinstance(x, list)
    if t == "string":
        return isinstance(x, str)
    if t == "boolean":
        return isinstance(x, bool)
    if t == "null":
        return x is None
    if t == "integer":
        return (isinstance(x, int) and not isinstance(x, bool)) or (isinstance(x, float) and x.is_integer())
    if t == "number":
        return isinstance(x, (int, float)) and not isinstance(x, bool)
    raise ValueError(f"unknown type {t!r} in schema")


def validate(instance, schema: dict, root: dict | None = None, path: str = "$") -> list[str]:
    """Every violation of ``schema`` by ``instance``, as ``"path: message"`` (empty when valid)."""
    root = schema if root is None else root
    errs: list[str] = []
    unknown = set(schema) - KEYWORDS
    if unknown:
        raise ValueError(f"{path}: schema keywords not supported by this validator: {sorted(unknown)}")
    if "$ref" in schema:
        ref = schema["$ref"]
        if not ref.startswith("#/$defs/"):
            raise ValueError(f"{path}: only #/$defs/ references are supported, got {ref}")
        errs += validate(instance, root["$defs"][ref[len("#/$defs/"):]], root, path)
    if "type" in schema:
        types = schema["type"] if isinstance(schema["type"], list) else [schema["type"]]
        if not any(_is_type(instance, t) for t in types):
            return errs + [f"{path}: expected {' or '.join(types)}, got {type(instance).__name__} {instance!r:.60}"]
    if "enum" in schema and instance not in schema["enum"]:
        errs.append(f"{path}: {instance!r} not one of {schema['enum']}")
    if "const" in schema and instance != schema["const"]:
        errs.append(f"{path}: {instance!r} != {schema['const']!r}")
    if isinstance(instance, str) and "pattern" in schema and not re.search(schema["pattern"], instance):
        errs.append(f"{path}: {instance!r:.60} does not match pattern {schema['pattern']!r}")
    if isinstance(instance, (int, float)) and not isinstance(instance, bool):
        if "minimum" in schema and instance < schema["minimum"]:
            errs.append(f"{path}: {instance} < minimum {schema['minimum']}")
        if "maximum" in schema and instance > schema["maximum"]:
            errs.append(f"{path}: {instance} > maximum {schema['maximum']}")
        if "exclusiveMinimum" in schema and instance <= schema["exclusiveMinimum"]:
            errs.append(f"{path}: {instance} <= exclusiveMinimum {schema['exclusiveMinimum']}")
    if isinstance(instance, dict):
        props = schema.get("properties", {})
        for k in schema.get("required", ()):
            if k not in instance:
                errs.append(f"{path}: missing required key {k!r}")
        for k, v in instance.items():
            if k in props:
                errs += validate(v, props[k], root, f"{path}.{k}")
            else:
                extra = schema.get("additionalProperties", True)
                if extra is False:
                    errs.append(f"{path}: unexpected key {k!r}")
                elif isinstance(extra, dict):
                    errs += validate(v, extra, root, f"{path}.{k}")
    if isinstance(instance, list):
        if "minItems" in schema and len(instance) < schema["minItems"]:
            errs.append(f"{path}: {len(instance)} items < minItems {schema['minItems']}")
        if "maxItems" in schema and len(instance) > schema["maxItems"]:
            errs.append(f"{path}: {len(instance)} items > maxItems {schema['maxItems']}")
        if "items" in schema:
            for i, v in enumerate(instance):
                errs += validate(v, schema["items"], root, f"{path}[{i}]")
    if "anyOf" in schema and not any(not validate(instance, s, root, path) for s in schema["anyOf"]):
        errs.append(f"{path}: matches none of anyOf")
    for s in schema.get("allOf", ()):
        errs += validate(instance, s, root, path)
    return errs
