"""A numpy model of cpt_track's occlusion measure (src/vision/track.rs, `occlusion`), used to choose
its threshold (docs/models/cpt.md): 2 px speckle rendered at 8x and area-downsampled like
vision::synthetic, a 20 px template, and the measure under a sigma = 1.2 px blur and under flat
(grey 70) or textured covers of a share f of the central half of the window (bars from the left,
squares at the centre's corner), 3 grey levels of noise, 200 random windows each. "fit" is the
measure shakeflow uses (residual over the fitted template's signal around the point); "patch" and
"sym" are two normalisations that were considered; "zncc" is the whole-window score.

    cpt_occlusion_model.py     (prints median, 5th and 95th percentiles and maximum per case)
"""
import numpy as np
from scipy import ndimage
rng=np.random.default_rng(1)
def texture(h,w):
    g=rng.uniform(20,235,size=(h//2+4,w//2+4))
    up=ndimage.zoom(g,16,order=3)[:h*8,:w*8]
    return up.reshape(h,8,w,8).mean(axis=(1,3))
m=20
def metrics(T,P,norm):
    t=T-T.mean(); v=P-P.mean()
    gain=(t*v).sum()/(t*t).sum()
    r=v-gain*t
    c=np.zeros_like(T,bool); o=(m-1)/2; reach=m/4
    yy,xx=np.mgrid[0:m,0:m]; c=(abs(xx-o)<=reach)&(abs(yy-o)<=reach)
    tc=t[c]-t[c].mean(); vc=v[c]-v[c].mean()
    res=(r[c]**2).sum(); sig=(gain*tc)**2; sig=sig.sum(); pe=(vc**2).sum()
    return {'fit':res/sig,'patch':res/pe,'sym':res/(sig+pe), 'zncc':(t*v).sum()/np.sqrt((t*t).sum()*(v*v).sum())}
out={}
for trial in range(200):
    img=texture(60,60); other=texture(60,60)
    T=img[20:40,20:40]
    noise=lambda a: a+rng.normal(0,3,a.shape)
    blur=ndimage.gaussian_filter(img,1.2)[20:40,20:40]
    res={'blur':metrics(T,noise(blur),0)}
    for f in [0.3,0.5,0.6,0.8]:
        # flat occluder covering the left part of the central block up to fraction f, vertical bar full height
        x1=int(round(5+ f*10))  # central block columns 5..14
        P=img[20:40,20:40].copy(); P[:, :x1]=70; res[f'flat{f}']=metrics(T,noise(P),0)
        P=img[20:40,20:40].copy(); P[:, :x1]=other[20:40,20:40][:, :x1]; res[f'tex{f}']=metrics(T,noise(P),0)
        # square covering fraction f of central block (a square of side sqrt(f)*10 at the centre corner)
        s=int(round(np.sqrt(f)*10)); P=img[20:40,20:40].copy(); P[5:5+s,5:5+s]=70; res[f'sq{f}']=metrics(T,noise(P),0)
    for k,v in res.items():
        for mk,mv in v.items(): out.setdefault((k,mk),[]).append(mv)
for (k,mk),vals in sorted(out.items()):
    vals=np.array(vals); print(f"{k:10s} {mk:6s} median {np.median(vals):.3f} p5 {np.percentile(vals,5):.3f} p95 {np.percentile(vals,95):.3f} max {vals.max():.3f}")
