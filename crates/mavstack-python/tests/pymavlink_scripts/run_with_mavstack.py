"""Runs a script written for pymavlink with mavstack's mavutil in its place: the script is
unchanged, its `from pymavlink import mavutil` gets `mavstack.mavutil`.

Usage: run_with_mavstack.py SCRIPT ARGS..."""
import runpy
import sys

import pymavlink
from mavstack import mavutil

sys.modules["pymavlink.mavutil"] = mavutil
pymavlink.mavutil = mavutil
script = sys.argv[1]
sys.argv = sys.argv[1:]
runpy.run_path(script, run_name="__main__")
