"""Everything that reads a mesh file or writes a file or the terminal: USD, the HTML player,
previews, frame sinks, OBJ/USD mesh readers, safe output files, provenance, progress lines.
Imports the layers below it; never ``warpcloth.run``."""
