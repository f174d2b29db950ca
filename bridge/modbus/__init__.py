"""EDGE: the only package that imports pymodbus and pyserial."""
