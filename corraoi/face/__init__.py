"""The top floor: what composes the engine with the recorder and the viewer (a run into its
files, a sweep with its outputs, tables for analysis)."""
