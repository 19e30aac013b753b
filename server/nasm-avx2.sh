#!/bin/sh
# nasm with OpenH264's AVX2 kernels switched on: see .cargo/config.toml.
exec nasm -DHAVE_AVX2 "$@"
