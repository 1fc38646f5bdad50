"""The leg's physics: a model (digital twin) of one ball-screw leg, at the bottom of the house.

Pure physics: numpy only, no I/O, no protocol, no clock of its own. Everything that needs to know
how a leg behaves reads it from here: the simulated drive and interferometers (drivers/sim), the
diagnosis' simulated-plant twin (procedures/diagnosis/twin.py) and the synthetic and sample
sessions (procedures/synthetic.py, station/services/samples.py). Procedures may import it
(tests/test_layering.py): it is a model of the leg, not a device.
"""
