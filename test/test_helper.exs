# `mix test` runs the quick tests; `bin/ringtracer test` (and CI) includes
# the slow, multi-node, network-namespace, browser and release ones too.
ExUnit.start(exclude: [:slow, :distributed, :network, :browser, :release])
