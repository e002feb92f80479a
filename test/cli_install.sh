#!/bin/sh
# make install into a staging folder; build a program against the installed
# copy through pkg-config; the header compiles as C99 and as C++; the
# shared library exports only rtp_ symbols.
TEST_NAME=install
. "$(dirname "$0")/common.sh"
CC=${CC:-cc}

# the build being tested (sanitizer builds pass their flags down)
if make -s install BUILD="${RTP_BUILD:-build}" ${RTP_CFLAGS:+CFLAGS="$RTP_CFLAGS"} \
        ${RTP_LDFLAGS:+LDFLAGS="$RTP_LDFLAGS"} DESTDIR="$T/stage" PREFIX=/opt/rtp >"$T/log" 2>&1; then ok
else bad "make install"; cat "$T/log" >&2; fi
# the soname: librtp.so.0.MINOR before 1.0 (a minor version may grow the
# public structs), librtp.so.MAJOR after
maj=$(sed -nE 's/^#define RTP_VERSION_MAJOR ([0-9]+).*/\1/p' include/rtp.h)
min=$(sed -nE 's/^#define RTP_VERSION_MINOR ([0-9]+).*/\1/p' include/rtp.h)
if [ "$maj" = 0 ]; then soname=librtp.so.0.$min; else soname=librtp.so.$maj; fi
for f in lib/librtp.a lib/librtp.so lib/$soname include/rtp.h bin/rtp lib/pkgconfig/rtp.pc; do
    [ -e "$T/stage/opt/rtp/$f" ] && ok || bad "not installed: $f"
done

cat > "$T/prog.c" <<'EOC'
#include <rtp.h>
#include <stdio.h>
int main(void)
{
    rtp_image *img = NULL;
    if (rtp_version_number() != RTP_VERSION_NUMBER) return 1;
    if (rtp_image_create(4, 3, NULL, &img, NULL) != RTP_OK) return 1;
    printf("%s %dx%d\n", rtp_version_string(), img->width, img->height);
    rtp_image_destroy(img);
    return 0;
}
EOC
if command -v pkg-config >/dev/null 2>&1; then
    export PKG_CONFIG_PATH="$T/stage/opt/rtp/lib/pkgconfig"
    export PKG_CONFIG_SYSROOT_DIR="$T/stage"
    # static: the archive plus what pkg-config says it needs privately
    if $CC -std=c99 $RTP_CFLAGS $RTP_LDFLAGS -o "$T/prog" "$T/prog.c" $(pkg-config --cflags rtp) \
           "$T/stage/opt/rtp/lib/librtp.a" $(pkg-config --static --libs rtp | sed 's/-lrtp//') 2>"$T/err"; then
        "$T/prog" >"$T/out" && grep -q "4x3" "$T/out" && ok || bad "static program run"
    else bad "build against installed static library"; cat "$T/err" >&2; fi
    # fully static, as pkg-config gives it: libpng's own needs (zlib) come
    # through Requires.private (a bare -lpng16 in Libs.private left
    # deflate undefined); not with sanitizers, nor without static libpng
    # (every library it names must exist as an archive: Debian ships no
    # libOSMesa.a, so the OSMesa build cannot link fully static)
    nostatic=""
    for l in $(pkg-config --static --libs rtp); do
        case $l in
        -lrtp | -lm | -lpthread | -lc) ;;
        -l*) a=$($CC -print-file-name="lib${l#-l}.a" 2>/dev/null)
             [ -f "$a" ] || nostatic="$nostatic lib${l#-l}.a" ;;
        esac
    done
    if [ -n "${RTP_CFLAGS##*-fsanitize*}" ] || [ -z "$RTP_CFLAGS" ]; then
        if [ -z "$nostatic" ]; then
            if $CC -std=c99 -static -o "$T/prog_static" "$T/prog.c" $(pkg-config --cflags rtp) \
                   $(pkg-config --static --libs rtp) 2>"$T/err"; then
                "$T/prog_static" >"$T/out" && grep -q "4x3" "$T/out" && ok || bad "fully static program run"
            else bad "fully static link with pkg-config --static --libs rtp"; cat "$T/err" >&2; fi
        else
            echo "skip: no$nostatic: fully static link not tried" >&2; skip=$((skip + 1))
        fi
    fi
    if $CC -std=c99 $RTP_CFLAGS $RTP_LDFLAGS -o "$T/prog_so" "$T/prog.c" $(pkg-config --cflags --libs rtp) 2>"$T/err"; then
        LD_LIBRARY_PATH="$T/stage/opt/rtp/lib" "$T/prog_so" >"$T/out" && grep -q "4x3" "$T/out" && ok || bad "shared program run"
    else bad "build against installed shared library"; cat "$T/err" >&2; fi
else
    echo "skip: pkg-config not installed" >&2; skip=$((skip + 1))
fi

# The header alone compiles as strict C99 and as C++.
echo '#include "rtp.h"' > "$T/h.c"
$CC -std=c99 -pedantic -Wall -Wextra -Werror -Iinclude -c "$T/h.c" -o "$T/h.o" && ok || bad "header as C99"
if command -v c++ >/dev/null 2>&1; then
    c++ -x c++ -std=c++11 -pedantic -Wall -Wextra -Werror -Iinclude -c "$T/h.c" -o "$T/hpp.o" && ok || bad "header as C++"
else
    echo "skip: no C++ compiler" >&2; skip=$((skip + 1))
fi

# Exported symbols: the shared library exports only rtp_*; the static
# library defines nothing outside the rtp_/rtpi_ namespace.
lib=${RTP_BUILD:-build}
if command -v nm >/dev/null 2>&1 && [ -f "$lib/librtp.so" ]; then
    badsyms=$(nm -D --defined-only "$lib/librtp.so" | awk '{print $3}' | grep -v '^rtp_' | grep -v '^_' )
    [ -z "$badsyms" ] && ok || bad "shared library exports: $badsyms"
    badsyms=$(nm --defined-only -g "$lib/librtp.a" 2>/dev/null | awk 'NF==3 {print $3}' | grep -v '^rtpi\?_')
    [ -z "$badsyms" ] && ok || bad "static library defines: $badsyms"
else
    echo "skip: nm or librtp.so missing" >&2; skip=$((skip + 1))
fi
rm -rf "$T"
echo "$pass passed, $fail failed, $skip skipped"
[ "$fail" -eq 0 ]
