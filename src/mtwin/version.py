"""mtwin's version, in a module of its own: the package root, the use cases and the command line
read it without importing one another."""
__version__ = "0.1.0"
