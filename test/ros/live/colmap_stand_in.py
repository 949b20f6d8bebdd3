#!/usr/bin/env python3
"""A stand-in for COLMAP that fails the way COLMAP can (issue 30's fault injection), put on
colmap_bridge's ~colmap path. Every call is logged to calls.txt beside it; anything not faulted
runs the real colmap. Faults, from faults.json beside it, each at most once unless said:

  hang_extraction   the first feature_extractor call hangs (until it is killed)
  bad_image         the first image of the second feature_extractor call fails every call that
                    lists it, for good (exit 1, "cannot read"); its name goes to bad_image.txt
  bad_pair          the first pair of the second matches_importer call fails every call that
                    lists it, for good (exit 3); it goes to bad_pair.txt
  kill_in           the first call of that command SIGKILLs itself (COLMAP crashing)
"""
import json
import os
import signal
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def state(name, default=None):
    path = os.path.join(HERE, name)
    return open(path).read().strip() if os.path.exists(path) else default


def mark(name, value="1"):
    with open(os.path.join(HERE, name), "w") as f:
        f.write(value)


def option(args, name):
    return args[args.index(name) + 1] if name in args else None


def main():
    args = sys.argv[1:]
    command = args[0] if args else ""
    faults = json.load(open(os.path.join(HERE, "faults.json")))
    count = int(state("count_" + command, "0")) + 1
    mark("count_" + command, str(count))
    with open(os.path.join(HERE, "calls.txt"), "a") as f:
        f.write("%s %d\n" % (command, count))
    if command == "feature_extractor":
        listed = [l.strip() for l in open(option(args, "--image_list_path")) if l.strip()]
        if faults.get("hang_extraction") and count == 1:
            time.sleep(3600)
        if faults.get("bad_image"):
            if count == 2 and not state("bad_image.txt"):
                mark("bad_image.txt", listed[0])
            if state("bad_image.txt") in listed:
                print("simulated: cannot read %s" % state("bad_image.txt"), file=sys.stderr)
                sys.exit(1)
    if command == "matches_importer" and faults.get("bad_pair"):
        listed = [" ".join(l.split()) for l in open(option(args, "--match_list_path")) if l.strip()]
        if count == 2 and not state("bad_pair.txt"):
            mark("bad_pair.txt", listed[0])
        if state("bad_pair.txt") in listed:
            print("simulated: matching %s crashed" % state("bad_pair.txt"), file=sys.stderr)
            sys.exit(3)
    if faults.get("kill_in") == command and not state("killed"):
        mark("killed")
        os.kill(os.getpid(), signal.SIGKILL)
    os.execvp("colmap", ["colmap"] + args)


if __name__ == "__main__":
    main()
