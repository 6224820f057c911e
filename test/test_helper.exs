# `mix test` runs the quick tests; `bin/ringtracer test` (and CI) includes
# the slow, multi-node and network-namespace ones too.
ExUnit.start(exclude: [:slow, :distributed, :network])
