"""The report's interactive 3-D view of the drawn modes: an HTML fragment that works offline (no
library, no network): the surface and the modes' displacements inline as base64 float32/uint32
arrays in a JSON block, and a canvas-2D renderer written here (about 150 lines of JavaScript).

The renderer draws what :mod:`fem_squeal.app.shape_pictures` draws, at any phase of one period:
the surface displaced by u(θ) = Re(e^{iθ}(a + i b)) = a cos θ − b sin θ, each triangle that faces
the viewer filled far ones first with the colour of its normal displacement u(θ)·n (the mean of its
corners on its undeformed normal; the scale of the pictures), shaded by the cosine to the view.
Drag: rotate; wheel: zoom; the slider: phase; ▶: one period per two seconds.  After its first
frame it writes ``data-viewer-triangles`` (triangles drawn) and ``data-viewer-variance`` (of the
canvas' grey levels) on its element, which the tests read in headless Chromium."""
from __future__ import annotations

import base64
import json

import numpy as np

from fem_squeal.app.shape_pictures import COLOURMAP, DEFORMATION, scales


def _b64(a: np.ndarray, dtype) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype=dtype).tobytes()).decode()


def _palette(n: int = 64) -> list[str]:
    """The pictures' colour map as ``n`` CSS colours from −1 to 1."""
    import matplotlib  # heavy: matplotlib (the report's 3-D view)

    rgb = matplotlib.colormaps[COLOURMAP](np.linspace(0.0, 1.0, n))[:, :3]
    return [f"#{int(255 * r):02x}{int(255 * g):02x}{int(255 * b):02x}" for r, g, b in rgb]


def viewer_data(shapes, labels: list[str]) -> dict:
    """The JSON block: surface, palette and per mode its label, displacement parts and scales."""
    extent = float(np.ptp(shapes.points, axis=0).max())
    modes = []
    for k, label in enumerate(labels):
        full, vmax = scales(shapes.u_re[k], shapes.u_im[k], shapes.un_re[k], shapes.un_im[k])
        modes.append({"label": label, "re": _b64(shapes.u_re[k], "<f4"), "im": _b64(shapes.u_im[k], "<f4"),
                      "scale": DEFORMATION * extent / full, "clip": 2.0 * full, "vmax": vmax})
    return {"points": _b64(shapes.points, "<f4"), "triangles": _b64(shapes.triangles, "<u4"),
            "palette": _palette(), "modes": modes}


SCRIPT = r"""(function(){
var root=document.getElementById('viewer');if(!root)return;
var D=JSON.parse(document.getElementById('viewer-data').textContent);
function f32(s){var b=atob(s),u=new Uint8Array(b.length);for(var i=0;i<b.length;i++)u[i]=b.charCodeAt(i);
return new Float32Array(u.buffer);}
function u32(s){var b=atob(s),u=new Uint8Array(b.length);for(var i=0;i<b.length;i++)u[i]=b.charCodeAt(i);
return new Uint32Array(u.buffer);}
var P=f32(D.points),T=u32(D.triangles),n=P.length/3,m=T.length/3,pal=D.palette.map(function(h){
return [parseInt(h.substr(1,2),16),parseInt(h.substr(3,2),16),parseInt(h.substr(5,2),16)];});
var modes=D.modes.map(function(o){return {label:o.label,re:f32(o.re),im:f32(o.im),scale:o.scale,clip:o.clip,
vmax:o.vmax};});
var c=[0,0,0],lo=[1e30,1e30,1e30],hi=[-1e30,-1e30,-1e30];
for(var i=0;i<n;i++)for(var d=0;d<3;d++){lo[d]=Math.min(lo[d],P[3*i+d]);hi[d]=Math.max(hi[d],P[3*i+d]);}
for(d=0;d<3;d++)c[d]=0.5*(lo[d]+hi[d]);
var ext=Math.max(hi[0]-lo[0],hi[1]-lo[1],hi[2]-lo[2])||1;
var N=new Float32Array(3*m);          // undeformed unit normals of the triangles
for(var t=0;t<m;t++){var a=3*T[3*t],b=3*T[3*t+1],e=3*T[3*t+2];
var ux=P[b]-P[a],uy=P[b+1]-P[a+1],uz=P[b+2]-P[a+2],vx=P[e]-P[a],vy=P[e+1]-P[a+1],vz=P[e+2]-P[a+2];
var nx=uy*vz-uz*vy,ny=uz*vx-ux*vz,nz=ux*vy-uy*vx,l=Math.hypot(nx,ny,nz)||1;
N[3*t]=nx/l;N[3*t+1]=ny/l;N[3*t+2]=nz/l;}
var cv=root.querySelector('canvas'),g=cv.getContext('2d'),sel=root.querySelector('select'),
ph=root.querySelector('input.phase'),amp=root.querySelector('input.amp'),btn=root.querySelector('button');
modes.forEach(function(o,k){var op=document.createElement('option');op.value=k;op.textContent=o.label;
sel.appendChild(op);});
var yaw=-120*Math.PI/180,pitch=30*Math.PI/180,zoom=1,X=new Float32Array(3*n),Q=new Float32Array(3*n),
depth=new Float32Array(m),order=new Uint32Array(m),un=new Float32Array(m),playing=false,last=0;
function frame(){
var o=modes[+sel.value||0],th=(+ph.value)*Math.PI/180,ct=Math.cos(th),st=Math.sin(th),
s=o.scale*(+amp.value)/100,cy=Math.cos(yaw),sy=Math.sin(yaw),cp=Math.cos(pitch),sp=Math.sin(pitch);
// camera: right (-sy, cy, 0), up (-sp cy, -sp sy, cp), towards the viewer (cp cy, cp sy, sp)
for(var i=0;i<n;i++){var ux=o.re[3*i]*ct-o.im[3*i]*st,uy=o.re[3*i+1]*ct-o.im[3*i+1]*st,
uz=o.re[3*i+2]*ct-o.im[3*i+2]*st,l=Math.hypot(ux,uy,uz),f=l>o.clip?o.clip/l:1;
X[3*i]=ux;X[3*i+1]=uy;X[3*i+2]=uz;
var x=P[3*i]-c[0]+s*f*ux,y=P[3*i+1]-c[1]+s*f*uy,z=P[3*i+2]-c[2]+s*f*uz;
Q[3*i]=-sy*x+cy*y;Q[3*i+1]=-sp*cy*x-sp*sy*y+cp*z;Q[3*i+2]=cp*cy*x+cp*sy*y+sp*z;}
var W=cv.width,H=cv.height,k=0,sc=0.85*zoom*Math.min(W,H)/ext;
for(var t=0;t<m;t++){var a=3*T[3*t],b=3*T[3*t+1],e=3*T[3*t+2];
var cr=(Q[b]-Q[a])*(Q[e+1]-Q[a+1])-(Q[b+1]-Q[a+1])*(Q[e]-Q[a]);
if(cr<=0)continue;
depth[t]=Q[a+2]+Q[b+2]+Q[e+2];order[k++]=t;
un[t]=((X[a]+X[b]+X[e])*N[3*t]+(X[a+1]+X[b+1]+X[e+1])*N[3*t+1]+(X[a+2]+X[b+2]+X[e+2])*N[3*t+2])/3;}
var vis=order.subarray(0,k);vis.sort(function(p,q){return depth[p]-depth[q];});
g.fillStyle='#fff';g.fillRect(0,0,W,H);
for(var j=0;j<k;j++){var t=vis[j],a=3*T[3*t],b=3*T[3*t+1],e=3*T[3*t+2];
var ux=Q[b]-Q[a],uy=Q[b+1]-Q[a+1],uz=Q[b+2]-Q[a+2],vx=Q[e]-Q[a],vy=Q[e+1]-Q[a+1],vz=Q[e+2]-Q[a+2];
var nz=ux*vy-uy*vx,sh=0.45+0.55*nz/(Math.hypot(uy*vz-uz*vy,uz*vx-ux*vz,nz)||1);
var v=Math.max(-1,Math.min(1,un[t]/o.vmax)),col=pal[Math.min(pal.length-1,Math.floor((v+1)/2*pal.length))];
g.fillStyle='rgb('+(col[0]*sh|0)+','+(col[1]*sh|0)+','+(col[2]*sh|0)+')';g.strokeStyle=g.fillStyle;g.lineWidth=0.5;g.beginPath();
g.moveTo(W/2+sc*Q[a],H/2-sc*Q[a+1]);g.lineTo(W/2+sc*Q[b],H/2-sc*Q[b+1]);g.lineTo(W/2+sc*Q[e],H/2-sc*Q[e+1]);
g.closePath();g.fill();g.stroke();}
return k;}
function redraw(){return frame();}
var drag=null;
cv.addEventListener('pointerdown',function(ev){drag=[ev.clientX,ev.clientY];cv.setPointerCapture(ev.pointerId);});
cv.addEventListener('pointerup',function(){drag=null;});
cv.addEventListener('pointermove',function(ev){if(!drag)return;yaw-=(ev.clientX-drag[0])*0.01;
pitch=Math.max(-1.57,Math.min(1.57,pitch+(ev.clientY-drag[1])*0.01));drag=[ev.clientX,ev.clientY];redraw();});
cv.addEventListener('wheel',function(ev){ev.preventDefault();zoom*=Math.exp(-ev.deltaY*0.001);redraw();},
{passive:false});
[sel,ph,amp].forEach(function(el){el.addEventListener('input',redraw);});
function tick(ts){if(!playing)return;if(last)ph.value=(+ph.value+(ts-last)*0.18)%360;last=ts;redraw();
requestAnimationFrame(tick);}
btn.addEventListener('click',function(){playing=!playing;btn.textContent=playing?'\u23f8':'\u25b6';last=0;
if(playing)requestAnimationFrame(tick);});
var drawn=frame(),px=g.getImageData(0,0,cv.width,cv.height).data,s1=0,s2=0,np=px.length/4;
for(var i=0;i<px.length;i+=4){var y=(px[i]+px[i+1]+px[i+2])/3;s1+=y;s2+=y*y;}
root.setAttribute('data-viewer-triangles',drawn);root.setAttribute('data-viewer-variance',(s2/np-(s1/np)*(s1/np)).toFixed(1));
})();"""


def viewer_html(shapes, labels: list[str]) -> str:
    """The 3-D view (an HTML fragment: controls, canvas, the data and the script)."""
    # "<" as its JSON escape: the block cannot end the script element early
    data = json.dumps(viewer_data(shapes, labels), separators=(",", ":")).replace("<", "\\u003c")
    return (f'<div id="viewer" class="viewer"><div><label>mode <select></select></label> '
            f'<button type="button" title="animate one period">\u25b6</button> '
            f'<label>phase θ <input class="phase" type="range" min="0" max="360" value="0"></label> '
            f'<label>amplitude <input class="amp" type="range" min="0" max="300" value="100"></label></div>'
            f'<canvas width="720" height="480"></canvas>'
            f'<p class="note">Drag to rotate, wheel to zoom. {len(shapes.points)} points, '
            f'{len(shapes.triangles)} triangles; colour: normal displacement (as the pictures); '
            f'u(θ) = a cos θ − b sin θ for the mode a + i b.</p>'
            f'<script type="application/json" id="viewer-data">{data}</script>'
            f"<script>{SCRIPT}</script></div>")
