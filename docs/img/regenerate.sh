#!/bin/sh
# The README's pictures, made by the project's own commands (run from the repository root;
# needs pip install -e '.[plot]'). The capture is 8 s of the emulator in virtual time
# (deterministic: seed 1); SRP stops at 5 s, so the timing plot and the monitor show a stale
# stream.
set -eu
eyeq_spi() { python3 -m eyeq_spi.cli "$@"; }  # this tree's code, as eyeq-spi runs it
cap=$(mktemp -d)/readme.pcapng
eyeq_spi demo --virtual-time --duration 8 --objects 10 --signs 10 \
    --stop-dasp EYEQ_VIS_SRP_MSG@5 --capture "$cap" > /dev/null || true  # NOT OK: stale SRP
test -s "$cap"
eyeq_spi plot "$cap" --birdseye --at 4 -o docs/img/birdseye.png
eyeq_spi plot "$cap" --birdseye --animate --start 3 --end 5 --fps 5 -o docs/img/birdseye.gif
eyeq_spi plot "$cap" --timing --name 'OBSTACLES|ROAD|SRP|DIAGNOSTIC|HOST_VEH' \
    -o docs/img/timing.png
eyeq_spi plot "$cap" --link -o docs/img/link.png
# the Foxglove scene's SceneUpdate messages drawn from above (needs '.[foxglove,test]')
eyeq_spi export "$cap" --mcap "${cap%.pcapng}.mcap" > /dev/null
python3 tools/foxglove_picture.py "${cap%.pcapng}.mcap" --at 4 -o docs/img/foxglove-scene.png \
    > /dev/null
eyeq_spi monitor --replay "$cap" --pace 0 --screenshot docs/img/monitor.svg > /dev/null
eyeq_spi monitor --replay "$cap" --pace 0 --screenshot docs/img/monitor-80x24.svg \
    --screenshot-size 80x24 > /dev/null
