defmodule RingTracer.Native do
  @moduledoc false
  # NIF stubs only. The library is built by Mix.Tasks.Compile.RingTracerNative
  # into priv/native/. Public modules above this one validate and document.

  @on_load :load_nif

  @doc false
  def load_nif do
    path = :filename.join(:code.priv_dir(:ring_tracer), ~c"native/libring_tracer_nif")

    case :erlang.load_nif(path, 0) do
      :ok ->
        :ok

      {:error, {reason, text}} ->
        IO.warn(
          "RingTracer could not load its native library #{path}.so (#{reason}: #{text}). " <>
            "Build it with `mix compile` (needs cargo), or run `./ringtracer test`."
        )

        :ok
    end
  end

  def scene_parse(_bytes, _format, _name, _scene_dir, _allow_dirs, _includes), do: err()
  def read_scene_file(_path), do: err()
  def scene_live_count, do: err()
  def scene_animation(_scene), do: err()
  def scene_frame(_scene, _frame), do: err()
  def scene_camera(_scene), do: err()
  def trace_atom(_scene, _settings, _start, _count), do: err()
  def trace_atom_short(_scene, _settings, _start, _count, _budget_us), do: err()
  def render_image(_scene, _settings, _threads), do: err()
  def row_work(_scene, _settings), do: err()
  def validate_settings(_settings), do: err()
  def write_image(_path, _width, _height, _pixels, _mode), do: err()
  def write_image_in(_dir, _name, _width, _height, _pixels, _mode), do: err()
  def encode_png(_width, _height, _pixels), do: err()
  def write_png8(_path, _width, _height, _pixels, _mode), do: err()
  def write_png8_in(_dir, _name, _width, _height, _pixels, _mode), do: err()
  def encode_png8(_width, _height, _pixels), do: err()
  def srgb8_base64(_pixels), do: err()
  def pixels_encode(_pixels, _format), do: err()
  def pixels_encode_dirty(_pixels, _format), do: err()
  def pixels_tint(_pixels, _colour), do: err()
  def pixels_tint_dirty(_pixels, _colour), do: err()
  def pixels_decode(_wire, _format, _count), do: err()
  def pixels_decode_dirty(_wire, _format, _count), do: err()
  def zstd_compress(_bytes), do: err()
  def zstd_decompress(_frames, _max_bytes), do: err()
  def to_srgb8_binary(_pixels), do: err()
  def to_srgb8_base64(_pixels), do: err()
  def settings_defaults, do: err()
  def settings_limits, do: err()
  def thread_cpu_us, do: err()
  def process_cpu_us, do: err()
  def ray_counters, do: err()
  def fs_write(_path, _data, _mode, _replace), do: err()
  def fs_write_in(_dir, _name, _data, _mode, _replace), do: err()
  def fs_probe(_path), do: err()
  def fs_read_private(_path, _max_bytes), do: err()
  def fs_check_trusted(_path, _public, _private), do: err()
  def fs_open_dir(_path), do: err()
  def fs_private_dir(_path, _may_exist), do: err()
  def fs_dir_path(_dir), do: err()
  def fs_keep(_dir, _name), do: err()
  def fs_put_back(_dir, _name, _kept), do: err()
  def fs_discard(_dir, _kept), do: err()

  defp err, do: :erlang.nif_error(:nif_not_loaded)
end
