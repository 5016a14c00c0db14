"""Configuration: the typed scenario declared once (`scenario`: each field's type, default, range and
description), the one decoder and one-line error of every input file (`schema`, on msgspec), TOML
loading, `--set` overrides, cross-field checks and dumping (`load`), bounds files (`bounds`), the study
file's schema (`study`), the reference pages rendered from the schema (`reference`), shared text IO
(`textio`) and the one-line input error (`errors`).  Knows nothing of plants or of running: a plant
validates its own inputs (`harness.plant.validate_plant`).
"""
