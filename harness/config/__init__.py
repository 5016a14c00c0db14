"""Configuration: the typed scenario (`scenario`), its schema and checkers (`schema`), TOML loading,
`--set` overrides, cross-checks and dumping (`load`), bounds files (`bounds`), shared text IO
(`textio`) and the one-line input error (`errors`).  Knows nothing of plants or of running: a plant
validates its own inputs (`harness.plant.validate_plant`).
"""
