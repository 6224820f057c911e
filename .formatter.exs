[
  inputs: ["{mix,.formatter}.exs", "native/mix_compiler.exs", "{config,lib,test}/**/*.{ex,exs}"]
]
