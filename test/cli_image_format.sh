#!/bin/sh
# The image formats' specifications against lib/image.c: test/image_format.py,
# a reader and writer of PFM, PPM and PNG written from the formats' own
# descriptions alone, reads every kind of image rtp writes (trace's, merge's of
# NaN, infinite and negative floats, diff's heat maps) to the values README
# says, writes every variant the formats allow (PFM either byte order and Pf,
# PPM P3/P6 of any maxval with comments, PNG of every colour type, bit depth,
# tRNS, Adam7, filter and ancillary chunk) for rtp to read to the values the
# format gives (through merge, diff, a texture and a bump map), and files rtp
# must refuse by name (cut at every length, headers that lie, bytes after the
# data, palette indices past the palette, sizes past the limit).  Skipped
# without python3.
TEST_NAME=images
. "$(dirname "$0")/common.sh"
need_python "the image formats' independent reader"
python3 test/image_format.py "$RTP" "$T"
