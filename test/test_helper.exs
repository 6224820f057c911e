# `mix test` runs the quick tests; `bin/ringtracer test` (and CI) includes
# the slow, multi-node, network-namespace, browser and release ones too.
# A test's time limit is three minutes, not ExUnit's one: a peer node's boot
# and join have deadlines of two minutes and one (RingTracer.LocalCluster);
# the tests' own waits have their own deadlines.
ExUnit.start(exclude: [:slow, :distributed, :network, :browser, :release], timeout: 180_000)
