defmodule RingTracer.SettingsTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Settings

  alias RingTracer.{Native, Options, Settings}

  test "the struct, the options and the kernel share one set of defaults, the kernel's" do
    defaults = Native.settings_defaults()
    assert Settings.defaults() == defaults
    assert Map.take(%Settings{width: 4, height: 4}, Map.keys(defaults)) == defaults

    {:ok, opts} = Options.validate([])
    assert Map.new(Keyword.take(opts, Map.keys(defaults))) == defaults
  end

  test "the default cut-off is the kernel's own value: it reaches the kernel unchanged" do
    # the kernel keeps an f32; the default is that f32 widened, not 1 / 255 rounded again
    <<f32::float-32>> = <<1 / 255::float-32>>
    assert Settings.defaults().cutoff == f32

    assert Native.validate_settings(Settings.to_native(%Settings{width: 2, height: 2})) ==
             {:ok, true}
  end
end
