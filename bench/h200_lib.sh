# Shared by bench/h200_session{4,5,6}.sh (sourced): the frame benchmark's sizes and scene, and
# copies of the tree with edits for A/B runs.
lb() { python3 -m app.cli "$@"; }
f="--cells 1024 --size 1920 1080 --frames 40"
k="--cells 1024 --size 3840 2160 --frames 20"
static="--scene bench/scenes/pool_static_boat.toml"
# variant_tree DIR SED FILE [SED FILE ...]: a copy of the tree in DIR with each sed applied to
# its file (says so when an edit changed nothing)
variant_tree() {
    local w=$1; shift
    rm -rf "$w" && mkdir -p "$w" && cp -r app kernels lbm raytrace scenes bench tests "$w"/
    while [ $# -gt 1 ]; do
        sed -i "$1" "$w/$2"
        cmp -s "$2" "$w/$2" && echo "$w: $2 unchanged"
        shift 2
    done
}
# in_tree DIR ARGS...: lbwater ARGS run from the copy in DIR
in_tree() { local w=$1; shift; (cd "$w" && PYTHONPATH=/tmp/site:$w python3 -m app.cli "$@"); }
# list_4k_and_pool OUT: the baseline scene at 3840x2160 and the pool at 1920x1080, each with the
# shadow list on and off (RenderSettings.shadow_list)
list_4k_and_pool() {
    local l
    for l in on off; do
        lb bench frame $k $static --shadow-list $l --out "$1/static4k_list$l" | tail -1
        lb bench frame $f --shadow-list $l --out "$1/pool_list$l" | tail -1
    done
}
