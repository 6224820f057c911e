defmodule RingTracer.Test.CDP do
  @moduledoc """
  A headless chromium driven through the DevTools protocol over
  `--remote-debugging-pipe` (JSON messages separated by NUL bytes, read by
  chromium on its fd 3 and written on its fd 4: here the port's stdin and
  stdout), attached to the page it opened.
  """

  defstruct [:port, :session, buffer: "", next: 1]

  @doc "Starts chromium on `url` (with its own profile in `dir`) and attaches to its page."
  def start(chromium, url, dir, size \\ {1280, 1000}) do
    {w, h} = size

    cmd =
      "exec #{chromium} --headless --no-sandbox --disable-gpu --hide-scrollbars " <>
        "--user-data-dir=#{dir} --window-size=#{w},#{h} --remote-debugging-pipe '#{url}' " <>
        "3<&0 4>&1 0</dev/null 1>/dev/null 2>/dev/null"

    port = Port.open({:spawn_executable, "/bin/sh"}, [:binary, :exit_status, args: ["-c", cmd]])
    cdp = %__MODULE__{port: port}
    # The first reply waits for chromium's cold start, which took over 30 s
    # with both cores busy and the rest of the suite running.
    {targets, cdp} = call(cdp, "Target.getTargets", %{}, 120_000)
    page = Enum.find(targets["targetInfos"], &(&1["type"] == "page"))

    {%{"sessionId" => session}, cdp} =
      call(cdp, "Target.attachToTarget", %{targetId: page["targetId"], flatten: true})

    %{cdp | session: session}
  end

  @doc "The value of a JavaScript expression in the page."
  def eval(cdp, expression) do
    {r, cdp} = call(cdp, "Runtime.evaluate", %{expression: expression, returnByValue: true})
    {get_in(r, ["result", "value"]), cdp}
  end

  @doc "A PNG of the page's viewport."
  def screenshot(cdp) do
    {r, cdp} = call(cdp, "Page.captureScreenshot", %{format: "png"})
    {Base.decode64!(r["data"]), cdp}
  end

  # What a page shows, for a failure's message.
  @page_state "JSON.stringify([document.body.dataset.state, document.body.dataset.seq] " <>
                ".concat(['status', 'framesdone', 'showing'].map(i => " <>
                "(document.getElementById(i) || {}).textContent)))"

  @doc "Waits until `expression` is true in the page, polling every 100 ms."
  def await(cdp, expression, ms \\ 60_000) do
    case eval(cdp, expression) do
      {true, cdp} ->
        cdp

      {_, cdp} when ms > 0 ->
        Process.sleep(100)
        await(cdp, expression, ms - 100)

      {_, cdp} ->
        {page, _} = eval(cdp, @page_state)
        raise "the page never had #{expression}; it shows #{page}"
    end
  end

  @doc "Ends chromium."
  def stop(%__MODULE__{port: port} = cdp) do
    _ = call(cdp, "Browser.close", %{}, 5_000)
  catch
    _, _ -> :ok
  after
    if Port.info(port) != nil, do: Port.close(port)
  end

  @doc "Sends a command (to the page once attached) and waits for its result."
  def call(cdp, method, params, timeout \\ 30_000) do
    id = cdp.next
    msg = %{id: id, method: method, params: params}
    msg = if cdp.session, do: Map.put(msg, :sessionId, cdp.session), else: msg
    true = Port.command(cdp.port, [:jiffy.encode(msg), 0])
    reply(%{cdp | next: id + 1}, id, timeout)
  end

  defp reply(cdp, id, timeout) do
    case :binary.split(cdp.buffer, <<0>>) do
      [json, rest] ->
        cdp = %{cdp | buffer: rest}

        case :jiffy.decode(json, [:return_maps]) do
          %{"id" => ^id, "result" => result} -> {result, cdp}
          %{"id" => ^id, "error" => error} -> raise "DevTools error: #{inspect(error)}"
          _event -> reply(cdp, id, timeout)
        end

      [_incomplete] ->
        port = cdp.port

        receive do
          {^port, {:data, data}} -> reply(%{cdp | buffer: cdp.buffer <> data}, id, timeout)
          {^port, {:exit_status, status}} -> raise "chromium exited with status #{status}"
        after
          timeout -> raise "no DevTools reply to #{id} within #{timeout} ms"
        end
    end
  end
end
