# Sourced by the scripts (not run): where the standalone builds go by default.
# Beside the checkout, not inside it: rosrun searches the whole package folder (the checkout) as
# well as the devel space, so a build folder inside it hands rosrun extra copies of every tool
# (the devel space again, catkin's install-space scripts, a `make install`) and rosrun stops at
# "You have chosen a non-unique executable". A catkin workspace keeps build/ and devel/ outside
# src/ for the same reason. Named build_<checkout>, not <checkout>_build: rosrun tells a devel-space
# relay from the script it runs by whether the path starts with the source folder's, as a string,
# and /x/view_selection_build/devel/... starts with /x/view_selection.
#   default_build_dir [SUFFIX]   prints <parent>/build_<checkout>[SUFFIX] (absolute)
#   warn_build_inside DIR        warns when DIR, or an old _build/, lies inside the checkout
VIEW_SELECTION_REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
default_build_dir() {
  echo "$(dirname "$VIEW_SELECTION_REPO")/build_$(basename "$VIEW_SELECTION_REPO")${1:-}"
}
warn_build_inside() {
  case "$1/" in
    "$VIEW_SELECTION_REPO"/*)
      echo "warning: the build folder $1 is inside the package folder: rosrun will find more than" \
           "one executable per tool (build beside it: unset BUILD_DIR)" >&2 ;;
  esac
  local old
  for old in "$VIEW_SELECTION_REPO"/_build*/devel; do
    [ -d "$old" ] && [ "$(dirname "$old")" != "$1" ] &&
      echo "warning: $(dirname "$old") is an old build folder inside the package folder; rosrun" \
           "finds its copies of the tools too: remove it (builds now go to $(default_build_dir))" >&2
  done
  return 0
}
