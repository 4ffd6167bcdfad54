"""The physics of pantohil as a plain library (numpy/scipy, no FMI): catenary operators, the HIL
iteration, pantograph and rig models, metrics and case files."""
