"""SunSpec: the model definitions as data, the walk of a device's model chain."""
