$m0 << EOD
2.000000 1.000000
EOD
set terminal pngcairo size 1000,650 enhanced font 'DejaVu Sans,10'
set output "/work/reference/comparison_test_merged_resolutions/penetration_vs_step.png"
set title 'Hip sweep: deepest muscle surface vertex in a bone against the step size'
set xlabel 'step\_deg [degrees per pose]'
set ylabel 'max penetration [mm]'
set grid
set key top left
set offsets graph 0.05, graph 0.05, graph 0.1, 0
plot $m0 using 1:2 with linespoints pt 7 title "fibremss"
set terminal svg size 1000,650 enhanced font 'DejaVu Sans,10'
set output "/work/reference/comparison_test_merged_resolutions/penetration_vs_step.svg"
set title 'Hip sweep: deepest muscle surface vertex in a bone against the step size'
set xlabel 'step\_deg [degrees per pose]'
set ylabel 'max penetration [mm]'
set grid
set key top left
set offsets graph 0.05, graph 0.05, graph 0.1, 0
plot $m0 using 1:2 with linespoints pt 7 title "fibremss"
unset output
