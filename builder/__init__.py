"""The offline stage: case -> FMU parameters, FMU packaging with pythonfmu, validation."""
