"""OpenCL C sources of iblbake, shipped as package data (see iblbake/device/programs.py)."""
