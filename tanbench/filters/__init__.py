"""The three TAN methods: tightly coupled PF with DVL or SBE beams, loosely coupled PF."""

METHODS = ("tight-dvl", "tight-sbe", "loose-dvl")
