"""many_seeds.py PREFIX N: over images PREFIX0.exr .. PREFIX{N-1}.exr, glass_tube's island (rows 22-23, cols 31-32, summed
luminance), the image mean and the sphere block (16x16 at (24,24), luminance) over the reference's, means and s.e."""
import sys, numpy as np
sys.path.insert(0,'.')
from exr_images import read
Y=np.array([0.2126,0.7152,0.0722]); pre=sys.argv[1]; n=int(sys.argv[2])
refrgb=read('../../../tests/scenes/references/glass_tube.exr'); ref=refrgb@Y
isl=[];mean=[];blk=[]
rb=refrgb[24:40,24:40].mean((0,1))
for s in range(n):
    im=read(f'{pre}{s}.exr')
    b=im[24:40,24:40].mean((0,1)); blk.append((b@(Y*rb/(Y@rb))/rb).sum() if False else (b@Y)/(rb@Y))
    im=im@Y
    isl.append(im[22:24,31:33].sum()); mean.append(im.mean()/ref.mean())
isl,mean,blk=map(np.array,(isl,mean,blk))
se=lambda x: x.std(ddof=1)/np.sqrt(len(x))
print(f"{pre} n={n}: island {isl.mean():.2f} +- {se(isl):.2f} (ref {ref[22:24,31:33].sum():.2f}), seeds island>5: {(isl>5).sum()}; image mean {mean.mean():.4f} +- {se(mean):.4f}; block lum {blk.mean():.3f} +- {se(blk):.3f}, >5% dark {(blk<0.95).sum()}")
