[
  inputs: [
    "{mix,.formatter}.exs",
    "native/mix_compiler.exs",
    "{config,lib,tools,test}/**/*.{ex,exs}"
  ]
]
