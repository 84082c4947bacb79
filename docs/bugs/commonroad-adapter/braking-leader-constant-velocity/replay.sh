#!/bin/sh
# Runs this finding again and checks it reproduces.
cd "$(dirname "$0")" && exec drivefuzz replay .
