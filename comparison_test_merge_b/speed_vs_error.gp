$line0 << EOD
1400 3 "fibremss"
EOD
set terminal pngcairo size 1000,650 enhanced font 'DejaVu Sans,10'
set output "/work/reference/comparison_test_merge_b/speed_vs_error.png"
set title "Speed against error: one line per method (its cost knob swept)"
set xlabel 'ms per pose (median wall time, log)'
set ylabel "RMS surface distance to the CalculiX reference [mm] (log)"
set logscale xy
set grid
set key outside right top font ',9'
set offsets graph 0.1, graph 0.1, graph 0.2, graph 0.2
plot $line0 using 1:2 with linespoints pt 7 ps 1.2 lw 2 lc 1 title "fibremss, threads not recorded", $line0 using 1:2:3 with labels offset char 0,1 font ',8' notitle
set terminal svg size 1000,650 enhanced font 'DejaVu Sans,10'
set output "/work/reference/comparison_test_merge_b/speed_vs_error.svg"
set title "Speed against error: one line per method (its cost knob swept)"
set xlabel 'ms per pose (median wall time, log)'
set ylabel "RMS surface distance to the CalculiX reference [mm] (log)"
set logscale xy
set grid
set key outside right top font ',9'
set offsets graph 0.1, graph 0.1, graph 0.2, graph 0.2
plot $line0 using 1:2 with linespoints pt 7 ps 1.2 lw 2 lc 1 title "fibremss, threads not recorded", $line0 using 1:2:3 with labels offset char 0,1 font ',8' notitle
unset output
