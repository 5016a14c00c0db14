"""Configuration: the typed schema of every input file declared once (`scenario`, `bounds`, `study`), its
one decoder and one-line errors (`schema`, `errors`), loading and overrides (`load`), the controller class
(`controller`), the generated reference (`reference`), file IO (`textio`, `assets`), process settings
(`runtime`).  Knows nothing of plants or of running."""
