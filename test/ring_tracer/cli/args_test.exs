defmodule RingTracer.CLI.ArgsTest do
  use ExUnit.Case, async: true
  doctest RingTracer.CLI.Args
end
