from gpr3d.cli.main import entry

entry()
