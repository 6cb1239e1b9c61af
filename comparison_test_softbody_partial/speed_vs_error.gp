$runs << EOD
105 3 "fibremss (resolution=40) (0/13 poses)"
175 3 "fibremss:threads=1 (resolution=40) (0/13 poses)"
EOD
set terminal pngcairo size 1000,650 enhanced font 'DejaVu Sans,10'
set output "/work/wt/material/comparison_test_softbody_partial/speed_vs_error.png"
set title 'Speed against error (one point per run; the FEM reference is the zero)'
set xlabel 'ms per step (median wall time, log)'
set ylabel 'RMS surface distance to FEM [mm] (log)'
set logscale xy
set grid
set key off
set label 2 '(k/N poses): RMS to FEM over the first k of N poses only (the FEM or the run failed or stopped)' at graph 0.01, graph 0.03 left font ',9' tc rgb '#b00000'
set offsets graph 0.15, graph 0.15, graph 0.15, graph 0.15
plot $runs using 1:2 with points pt 7 ps 1.5 lc rgb '#1f77b4', $runs using 1:2:(int($0) % 2 ? '' : stringcolumn(3)) with labels offset char 0,1.2 font ',9', $runs using 1:2:(int($0) % 2 ? stringcolumn(3) : '') with labels offset char 0,-1.2 font ',9'
set terminal svg size 1000,650 enhanced font 'DejaVu Sans,10'
set output "/work/wt/material/comparison_test_softbody_partial/speed_vs_error.svg"
set title 'Speed against error (one point per run; the FEM reference is the zero)'
set xlabel 'ms per step (median wall time, log)'
set ylabel 'RMS surface distance to FEM [mm] (log)'
set logscale xy
set grid
set key off
set label 2 '(k/N poses): RMS to FEM over the first k of N poses only (the FEM or the run failed or stopped)' at graph 0.01, graph 0.03 left font ',9' tc rgb '#b00000'
set offsets graph 0.15, graph 0.15, graph 0.15, graph 0.15
plot $runs using 1:2 with points pt 7 ps 1.5 lc rgb '#1f77b4', $runs using 1:2:(int($0) % 2 ? '' : stringcolumn(3)) with labels offset char 0,1.2 font ',9', $runs using 1:2:(int($0) % 2 ? stringcolumn(3) : '') with labels offset char 0,-1.2 font ',9'
unset output
