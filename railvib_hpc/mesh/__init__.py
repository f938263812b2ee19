"""The finite-element model of the site: block layout, building, gmsh geometry, mesh files."""
