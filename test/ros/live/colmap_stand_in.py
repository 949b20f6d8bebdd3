#!/usr/bin/env python3
"""A stand-in for COLMAP that fails the way COLMAP can (issue 30's fault injection), put on
colmap_bridge's ~colmap path. Every call is logged to calls.txt beside it; anything not faulted
runs the real colmap. Faults, from faults.json beside it, each at most once unless said:

  hang_extraction   the first feature_extractor call hangs (until it is killed)
  bad_image         the first image of the second feature_extractor call (or the first call after
                    it that lists another image than the hanging one) fails every call that
                    lists it, for good (exit 1, "cannot read"); its name goes to bad_image.txt
  bad_pair          the first pair of the second matches_importer call (or of the first after it
                    that lists another pair than the hanging one) fails every call that
                    lists it, for good (exit 3); it goes to bad_pair.txt
  kill_in           the first call of that command SIGKILLs itself (COLMAP crashing)
  hang_image        N: every feature_extractor call that lists the Nth image of DIR/images (by
                    name; the names are stamps, so it stays the Nth) hangs until it is killed,
                    for good; its name goes to hang_image.txt
  hang_pair         [N, M]: every matches_importer call that lists the pair of the Nth and the Mth
                    image hangs until it is killed, for good; it goes to hang_pair.txt
bad_image and bad_pair are never the hanging image or pair.
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


def nth_images(folder, numbers):
    """The Nth images (1-based) of the project's image folder by name, or None while it has
    fewer; named as COLMAP's lists name them (relative: the node writes DIR/images/rgb/...)."""
    names = sorted(os.path.relpath(os.path.join(d, f), folder) for d, _, files in os.walk(folder) for f in files
                   if f.endswith(".png"))
    return [names[n - 1] for n in numbers] if len(names) >= max(numbers) else None


def hang(what):
    print("simulated: hanging on %s" % what, file=sys.stderr)
    sys.stderr.flush()
    time.sleep(3600)


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
        hanging = None
        if faults.get("hang_image"):
            hanging = state("hang_image.txt")
            found = None if hanging else nth_images(option(args, "--image_path"), [faults["hang_image"]])
            if found:
                hanging = found[0]
                mark("hang_image.txt", hanging)
            if hanging in listed:
                hang(hanging)
        if faults.get("hang_extraction") and count == 1:
            time.sleep(3600)
        if faults.get("bad_image"):
            if count >= 2 and not state("bad_image.txt") and [n for n in listed if n != hanging]:
                mark("bad_image.txt", [n for n in listed if n != hanging][0])
            if state("bad_image.txt") in listed:
                print("simulated: cannot read %s" % state("bad_image.txt"), file=sys.stderr)
                sys.exit(1)
    if command == "matches_importer":
        listed = [" ".join(l.split()) for l in open(option(args, "--match_list_path")) if l.strip()]
        hanging = None
        if faults.get("hang_pair"):
            hanging = state("hang_pair.txt")
            found = None if hanging else nth_images(
                os.path.join(os.path.dirname(option(args, "--database_path")), "images"), faults["hang_pair"])
            if found:
                hanging = " ".join(sorted(found))
                mark("hang_pair.txt", hanging)
            if hanging in listed:
                hang(hanging)
    if command == "matches_importer" and faults.get("bad_pair"):
        if count >= 2 and not state("bad_pair.txt") and [p for p in listed if p != hanging]:
            mark("bad_pair.txt", [p for p in listed if p != hanging][0])
        if state("bad_pair.txt") in listed:
            print("simulated: matching %s crashed" % state("bad_pair.txt"), file=sys.stderr)
            sys.exit(3)
    if faults.get("kill_in") == command and not state("killed"):
        mark("killed")
        os.kill(os.getpid(), signal.SIGKILL)
    os.execvp("colmap", ["colmap"] + args)


if __name__ == "__main__":
    main()
