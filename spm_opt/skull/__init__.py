"""The skull's surface from imaging: meshes, markups, registration, bone."""
