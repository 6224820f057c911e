# `mix test` runs the quick tests; `bin/ringtracer test` (and CI) includes
# the slow and multi-node ones too.
ExUnit.start(exclude: [:slow, :distributed, :browser])
