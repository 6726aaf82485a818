"""The ground floor: errors, atomic file writes, Ctrl-C, input limits, strict TOML fields,
output paths, markdown tables, the one local ruckig call, the parser's choices, the version.
Nothing here imports the rest of the package.
"""
